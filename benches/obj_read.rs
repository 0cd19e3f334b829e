//! Times the parallel OBJ reader ([`pathgrad::scene::mesh_io::load_obj`]) against the `tobj`-based
//! one it replaced (`load_obj_tobj`, feature `obj-oracle`) on one file, interleaved, and checks
//! that they agree.
//!
//! ```text
//! python3 benches/big_mesh.py 2000000 /tmp/big --obj
//! cargo bench --offline --features obj-oracle --bench obj_read -- /tmp/big/bumpy_2000000.obj [ROUNDS]
//! ```
//!
//! Prints one line per read (`reader round seconds`), then each reader's median; the geometry of
//! the two must be equal (a file whose objects share vertices differs by design: see
//! `src/scene/mesh_io/obj.rs`).

use std::path::PathBuf;
use std::time::Instant;

use pathgrad::scene::mesh_io::{load_obj, load_obj_tobj};

fn main() {
    // `cargo bench` appends `--bench`; the file and the round count are the other arguments.
    let args: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with("--")).collect();
    let Some(path) = args.first().map(PathBuf::from) else {
        eprintln!("usage: cargo bench --offline --features obj-oracle --bench obj_read -- FILE.obj [ROUNDS]");
        std::process::exit(2);
    };
    let rounds: usize = args.get(1).map_or(3, |r| r.parse().expect("ROUNDS is a number"));
    println!("{}: {} rayon threads", path.display(), rayon::current_num_threads());
    let mut times = [Vec::new(), Vec::new()];
    let mut results = [None, None];
    for round in 0..rounds {
        for (r, (name, read)) in
            [("tobj", load_obj_tobj as fn(&std::path::Path) -> _), ("parallel", load_obj)].into_iter().enumerate()
        {
            let start = Instant::now();
            let geometry = read(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
            let seconds = start.elapsed().as_secs_f64();
            println!(
                "{name:8} round {round}: {seconds:.3} s ({} vertices, {} triangles)",
                geometry.positions.len(),
                geometry.indices.len()
            );
            times[r].push(seconds);
            results[r] = Some(geometry);
        }
    }
    assert!(results[0] == results[1], "the readers disagree on {}", path.display());
    for (name, mut t) in ["tobj", "parallel"].into_iter().zip(times) {
        t.sort_by(f64::total_cmp);
        println!("{name:8} median {:.3} s (min {:.3}, max {:.3})", t[t.len() / 2], t[0], t[t.len() - 1]);
    }
    println!("geometry equal: yes");
}
