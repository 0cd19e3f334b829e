//! The library's names of options (`RenderOptions::spp`, `Loss`, …) spelled as this CLI's flags,
//! or as the keys of a batch manifest.
//!
//! Library errors name what a library user sets; the CLI shows the same messages with the flag a
//! command-line user types instead, and `batch` with the key a manifest's item has.

/// (library name, flag). A name counts only where it is not part of a longer name or path.
const FLAGS: &[(&str, &str)] = &[
    ("RenderOptions::width/height", "--width/--height"),
    ("RenderOptions::spp", "--spp"),
    ("RenderOptions::max_depth", "--max-depth"),
    ("LossGradientSetup::spp_primal", "--spp-primal"),
    ("LossGradientSetup::params", "--param"),
    ("Strategy::Diff::q", "--q"),
    ("Strategy::from_name", "--strategy"),
    ("PlacementMis::from_name", "--placement-mis"),
    ("AdamOptions::learning_rate", "--lr"),
    ("AdamOptions::beta1", "--beta1"),
    ("AdaptiveEstimator", "--adaptive-estimator"),
    ("GradMode::Deterministic", "--deterministic"),
    ("LoadOptions::allow_outside_folder", "--allow-outside-folder"),
    ("LoadOptions::environment_map", "--env"),
    ("LoadOptions::environment", "--env"),
    ("DeviceChoice", "--device"),
    ("variance::runs", "--runs"),
    ("Loss", "--loss"),
];

/// (library name, manifest key) where a batch item sets the option by another name than a flag.
const KEYS: &[(&str, &str)] = &[
    ("RenderOptions::width/height", "'width'/'height'"),
    ("RenderOptions::spp", "'spp'"),
    ("RenderOptions::max_depth", "'max_depth'"),
    ("GradMode::Deterministic", "'deterministic'"),
    ("LoadOptions::environment_map", "'env'"),
    ("LoadOptions::environment", "'env'"),
    ("Loss", "'loss'"),
];

/// Phrases of library messages that read differently on the command line.
const PHRASES: &[(&str, &str)] =
    &[("or None for unbounded", "or -1 for unbounded"), ("(None, unbounded,", "(-1, unbounded,")];

fn is_name_char(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// `text` with every library option name replaced by its flag.
pub fn with_flags(text: &str) -> String {
    renamed(text, &[FLAGS])
}

/// `text` with every library option name replaced by the batch manifest's key, or by its flag
/// where a manifest has no key of its own.
pub fn with_keys(text: &str) -> String {
    renamed(text, &[KEYS, FLAGS])
}

/// `text` with every library option name replaced by its name in the first of `tables` that has it.
fn renamed(text: &str, tables: &[&[(&str, &str)]]) -> String {
    let mut text = text.to_string();
    for (library, cli) in PHRASES {
        text = text.replace(library, cli);
    }
    let mut out = String::with_capacity(text.len());
    let mut rest = text.as_str();
    let mut previous: Option<char> = None;
    'scan: while let Some(c) = rest.chars().next() {
        let starts_name = previous.is_none_or(|p| !is_name_char(p) && p != ':');
        if starts_name {
            for (library, cli) in tables.iter().flat_map(|t| t.iter()) {
                if let Some(after) = rest.strip_prefix(library) {
                    let ends_name = match after.chars().next() {
                        None => true,
                        Some(n) => !is_name_char(n) && !after.starts_with("::"),
                    };
                    if ends_name {
                        out.push_str(cli);
                        previous = library.chars().last();
                        rest = after;
                        continue 'scan;
                    }
                }
            }
        }
        out.push(c);
        previous = Some(c);
        rest = &rest[c.len_utf8()..];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::with_flags;

    #[test]
    fn library_names_become_flags_only_where_they_stand_alone() {
        assert_eq!(with_flags("invalid Loss: 'x' (expected l1)"), "invalid --loss: 'x' (expected l1)");
        assert_eq!(with_flags("invalid RenderOptions::spp: must be"), "invalid --spp: must be");
        assert_eq!(with_flags("LossGradientSetup::spp_primal"), "--spp-primal");
        assert_eq!(with_flags("Lossy Loss::L1 NoLoss"), "Lossy Loss::L1 NoLoss");
        assert_eq!(
            with_flags("invalid RenderOptions::max_depth: must be at least 1 (or None for unbounded)"),
            "invalid --max-depth: must be at least 1 (or -1 for unbounded)"
        );
        assert_eq!(
            super::with_keys("invalid RenderOptions::width/height: must be; Strategy::Diff::q"),
            "invalid 'width'/'height': must be; --q"
        );
    }
}
