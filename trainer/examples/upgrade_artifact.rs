//! Rewrites model artifacts in the current format (the trainer reads every earlier format; the
//! runtime reads this one and the one before it), weights unchanged:
//!
//! ```sh
//! cargo run --release -p mochi-trainer --example upgrade_artifact -- tests/artifacts/*.mochi
//! ```

use mochi_trainer::artifact::Artifact;
use std::path::Path;

fn main() {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    if paths.is_empty() {
        eprintln!("usage: upgrade_artifact FILE.mochi...");
        std::process::exit(2);
    }
    for path in paths {
        let path = Path::new(&path);
        let result = Artifact::read(path)
            .map_err(|e| e.to_string())
            .and_then(|artifact| artifact.write(path).map_err(|e| e.to_string()));
        match result {
            Ok(()) => println!("{}: written in the current format", path.display()),
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        }
    }
}
