//! `<include>` and `<path>`: a scene file with the files it includes spliced into its text, and
//! where each byte of that text came from (so that messages name the included file and line).
//!
//! As Mitsuba 3.9.1 (`src/core/parser.cpp`): a `<path value="…"/>` (a child of `<scene>`, also
//! in an included file) adds a folder to the front of the search list, resolved beside the file
//! that names it; `<include filename="…"/>` finds its file in that list (the `<path>` folders
//! named so far, the latest first, then the scene's folder), and the included file's `<scene>`
//! children take its place, recursively, at most `MAX_DEPTH` deep. Files that objects name
//! (meshes, bitmaps, grids) are looked up the same way, with every `<path>` of the scene.
//! Folders and files obey the scene's folder rule ([`LoadOptions::allow_outside_folder`]).
//!
//! pathgrad reads `<include>` only as a child of `<scene>` (where every scene we know of puts
//! it) and refuses it elsewhere by name.
//!
//! [`LoadOptions::allow_outside_folder`]: crate::scene::LoadOptions::allow_outside_folder

use std::path::{Path, PathBuf};

use super::xml::Xml;
use crate::error::{Error, Result};
use crate::scene::load::scene_file;

/// Mitsuba's limit on nested `<include>`s (`MI_XML_INCLUDE_MAX_RECURSION`).
const MAX_DEPTH: usize = 15;

/// The spliced text and its pieces' origins.
pub(super) struct Sources {
    /// The scene's text with every `<include>` replaced by the included file's `<scene>` children.
    pub text: String,
    /// Runs of `text`, in order: (start in `text`, file index, start in that file's text).
    pieces: Vec<(usize, usize, usize)>,
    /// Every file read: the name messages show, and its text.
    files: Vec<(String, String)>,
    /// The `<path>` folders, the latest first (searched before the scene's folder).
    pub search: Vec<PathBuf>,
}

impl Sources {
    /// `file:line:col` of byte `offset` of the spliced text, in the file it came from.
    pub fn location(&self, offset: usize) -> String {
        let i = self.pieces.partition_point(|p| p.0 <= offset).saturating_sub(1);
        let (start, file, source) = self.pieces.get(i).copied().unwrap_or((0, 0, 0));
        let (name, text) = &self.files[file];
        let at = (source + offset.saturating_sub(start)).min(text.len());
        let before = &text[..at];
        let row = before.matches('\n').count() + 1;
        let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        format!("{name}:{row}:{col}")
    }
}

/// Reads `text` (the scene file `name`, in folder `dir`) with its includes spliced in.
///
/// # Errors
/// Malformed XML in any file (located in it), an included file that is missing, unreadable, not
/// a `<scene>`, included within itself or nested too deep, a `<path>` folder that does not exist,
/// and files or folders outside the scene's folder unless `allow_outside`.
pub(super) fn splice(name: &str, text: &str, dir: &Path, allow_outside: bool) -> Result<Sources> {
    let mut s = Splicer {
        out: Sources { text: String::new(), pieces: Vec::new(), files: Vec::new(), search: Vec::new() },
        dir: dir.to_path_buf(),
        allow_outside,
        stack: Vec::new(),
    };
    s.out.files.push((name.to_string(), text.to_string()));
    s.expand(0, None, dir)?;
    Ok(s.out)
}

/// Finds `name` along `search` then `dir` (the first folder where it exists; else `dir`'s),
/// under the folder rule. The folder rule's message is the one for `dir`.
pub(super) fn find(
    search: &[PathBuf],
    dir: &Path,
    name: &str,
    allow_outside: bool,
) -> std::result::Result<PathBuf, String> {
    for folder in search {
        if let Ok(path) = scene_file(folder, name, allow_outside)
            && path.exists()
        {
            return Ok(path);
        }
    }
    scene_file(dir, name, allow_outside)
}

struct Splicer {
    out: Sources,
    dir: PathBuf,
    allow_outside: bool,
    /// The files being expanded, outermost first (canonical paths), to refuse a cycle.
    stack: Vec<PathBuf>,
}

impl Splicer {
    /// Appends file `index`'s text (all of it for the scene file, its root's children for an
    /// included one, `included` = the `<include>` element's location) with its includes expanded.
    fn expand(&mut self, index: usize, included: Option<&str>, file_dir: &Path) -> Result<()> {
        let (name, text) = self.out.files[index].clone();
        let parsing =
            roxmltree::ParsingOptions { allow_dtd: false, nodes_limit: super::loader::MAX_NODES, ..Default::default() };
        let doc = roxmltree::Document::parse_with_options(&text, parsing).map_err(|e| {
            let pos = e.pos();
            let message = e.to_string().replace(&format!(" at {pos}"), "");
            let location = format!("{name}:{}:{}", pos.row, pos.col);
            let message = match included {
                Some(at) => format!("malformed XML (included at {at}): {message}"),
                None => format!("malformed XML: {message}"),
            };
            Error::Scene { location, message }
        })?;
        let root = doc.root_element();
        let x = Xml::new(name.clone(), &doc);
        let range = match included {
            None => 0..text.len(),
            Some(at) => {
                if root.tag_name().name() != "scene" {
                    return Err(
                        x.err(root, format!("an included file's root element must be <scene> (included at {at})"))
                    );
                }
                match (root.first_child(), root.last_child()) {
                    (Some(first), Some(last)) => first.range().start..last.range().end,
                    _ => 0..0,
                }
            }
        };
        let mut cursor = range.start;
        for c in root.children().filter(|c| c.is_element()) {
            let err = |message: String| x.err(c, message);
            let attribute = |name: &str| -> Result<&str> {
                x.check_attrs(c, &[name])?;
                c.attribute(name).ok_or_else(|| err(format!("missing attribute '{name}'")))
            };
            match c.tag_name().name() {
                "path" => {
                    let value = attribute("value")?;
                    // Beside the file that names it, else along the search list (Mitsuba's order).
                    let folder = match scene_file(file_dir, value, self.allow_outside) {
                        Ok(beside) if beside.is_dir() => beside,
                        beside => {
                            find(&self.out.search, &self.dir, value, self.allow_outside).or(beside).map_err(err)?
                        }
                    };
                    if !folder.is_dir() {
                        return Err(err(format!("folder '{value}' not found (looked for {})", folder.display())));
                    }
                    self.out.search.insert(0, folder);
                }
                "include" => {
                    let value = attribute("filename")?;
                    let path = find(&self.out.search, &self.dir, value, self.allow_outside).map_err(err)?;
                    if !path.is_file() {
                        return Err(err(format!("included file '{value}' not found (looked for {})", path.display())));
                    }
                    let real = path.canonicalize().unwrap_or_else(|_| path.clone());
                    if self.stack.contains(&real) {
                        return Err(err(format!("'{value}' includes itself")));
                    }
                    if self.stack.len() >= MAX_DEPTH {
                        return Err(err(format!("more than {MAX_DEPTH} nested includes")));
                    }
                    let bytes = std::fs::read(&path).map_err(|source| Error::Io { path: path.clone(), source })?;
                    let included_text = String::from_utf8(bytes).map_err(|e| Error::Scene {
                        location: path.display().to_string(),
                        message: format!("not UTF-8 text (invalid byte at offset {})", e.utf8_error().valid_up_to()),
                    })?;
                    self.piece(index, &text, cursor..c.range().start);
                    cursor = c.range().end;
                    self.out.files.push((path.display().to_string(), included_text));
                    self.stack.push(real);
                    let parent = path.parent().map(Path::to_path_buf).unwrap_or_default();
                    self.expand(self.out.files.len() - 1, Some(&x.loc(c)), &parent)?;
                    self.stack.pop();
                }
                _ => {}
            }
        }
        self.piece(index, &text, cursor..range.end);
        Ok(())
    }

    fn piece(&mut self, file: usize, text: &str, range: std::ops::Range<usize>) {
        if !range.is_empty() {
            self.out.pieces.push((self.out.text.len(), file, range.start));
            self.out.text.push_str(&text[range]);
        }
    }
}
