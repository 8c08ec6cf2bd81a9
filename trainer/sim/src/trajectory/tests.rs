//! Tests of `trajectory`.

use super::*;
use crate::npz::entry_options;
use npyz::zip;
use npyz::WriterBuilder;
use std::fs::File;
use std::io::Cursor;
use std::process::Command;

fn sample() -> Trajectory {
    let frames = 4;
    let n = 5;
    let dim = 3;
    let positions = (0..frames)
        .map(|f| {
            (0..n * dim)
                .map(|i| (i as f64 * 0.1 + f as f64).sin() / 3.0 + 1e-300 * f as f64)
                .collect()
        })
        .collect();
    Trajectory {
        scene: "cloth-flag ☃".into(),
        dt: 1.0 / 60.0,
        dim,
        positions,
        bc_signal: (0..frames).map(|f| vec![f as f64 * 0.5, -0.25]).collect(),
        energy_names: vec!["inertia".into(), "elastic".into(), "gravity".into()],
        energies: (0..frames)
            .map(|f| vec![f as f64, 1.0 / (f as f64 + 3.0), -9.81 * f as f64])
            .collect(),
        newton_iterations: vec![0, 3, 4, 2],
        step_seconds: vec![0.0, 1.5e-3, 2.25e-3, 1.0e-3],
        meta: vec![
            ("seed".into(), "42".into()),
            ("split".into(), "train".into()),
            ("note".into(), String::new()),
        ],
        obstacles: Some(ObstacleFrames {
            faces: vec![[0, 1, 2], [0, 2, 3]],
            positions: (0..frames)
                .map(|f| (0..12).map(|i| i as f64 * 0.25 - 0.01 * f as f64).collect())
                .collect(),
        }),
        colliders: Some(ColliderFrames {
            names: vec!["finger".into(), "ball".into()],
            shapes: vec![[1.0, 0.02, 0.05, 0.0], [0.0, 0.1, 0.0, 0.0]],
            states: (0..frames)
                .map(|f| (0..2 * COLLIDER_STATE).map(|i| (i as f64 - f as f64) * 0.125).collect())
                .collect(),
        }),
    }
}

#[test]
fn trajectory_npz_round_trip_is_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.npz");
    let t = sample();
    t.write_npz(&path).unwrap();
    let back = Trajectory::read_npz(&path).unwrap();
    assert_eq!(back, t);
    let bits = |t: &Trajectory| -> Vec<u64> { t.positions.iter().flatten().map(|v| v.to_bits()).collect() };
    assert_eq!(bits(&back), bits(&t));
    assert_eq!(back.dt.to_bits(), t.dt.to_bits());
    assert_eq!(back.meta_value("split"), Some("train"));
}

#[test]
fn trajectory_round_trip_without_bc_energies_or_meta_in_2d() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t2.npz");
    let t = Trajectory {
        scene: "beam2d".into(),
        dt: 0.01,
        dim: 2,
        positions: vec![vec![0.0, 0.0, 1.0, 0.0, 0.0, 1.0]; 2],
        bc_signal: vec![vec![]; 2],
        energy_names: vec![],
        energies: vec![vec![]; 2],
        newton_iterations: vec![0, 1],
        step_seconds: vec![0.0, 0.5],
        meta: vec![],
        obstacles: None,
        colliders: None,
    };
    t.write_npz(&path).unwrap();
    assert_eq!(Trajectory::read_npz(&path).unwrap(), t);
}

#[test]
fn trajectory_validate_names_the_field() {
    let mut t = sample();
    t.energies[2][1] = f64::NAN;
    assert!(t.validate().unwrap_err().starts_with("energies"));
    let mut t = sample();
    t.step_seconds.pop();
    assert!(t.validate().unwrap_err().starts_with("step_seconds"));
    let mut t = sample();
    t.positions[1].pop();
    assert!(t.validate().unwrap_err().starts_with("positions"));
    let mut t = sample();
    t.bc_signal[3].push(1.0);
    assert!(t.validate().unwrap_err().starts_with("bc_signal"));
    let mut t = sample();
    t.obstacles.as_mut().unwrap().faces.push([0, 1, 4]);
    assert!(t.validate().unwrap_err().starts_with("obstacle_faces"));
    let mut t = sample();
    t.obstacles.as_mut().unwrap().positions.pop();
    assert!(t.validate().unwrap_err().starts_with("obstacle_positions"));
    let mut t = sample();
    t.dim = 4;
    assert!(t.validate().is_err());
    let dir = tempfile::tempdir().unwrap();
    assert!(t.write_npz(&dir.path().join("bad.npz")).is_err());
}

#[test]
fn trajectory_truncated_or_corrupt_npz_is_an_input_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("good.npz");
    sample().write_npz(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let bad = dir.path().join("bad.npz");
    let mut cases = 0;
    // Every truncation length on a coarse grid, and a byte flip at many positions.
    for cut in (0..bytes.len()).step_by(11) {
        std::fs::write(&bad, &bytes[..cut]).unwrap();
        let e = Trajectory::read_npz(&bad).unwrap_err();
        assert_eq!(e.file, bad);
        cases += 1;
    }
    for at in (0..bytes.len()).step_by(7) {
        let mut flipped = bytes.clone();
        flipped[at] ^= 0x5a;
        std::fs::write(&bad, &flipped).unwrap();
        // A flip may land in a part nothing reads (e.g. a zip comment field); it must
        // never panic, and an error must name the file.
        if let Err(e) = Trajectory::read_npz(&bad) {
            assert_eq!(e.file, bad);
            cases += 1;
        }
    }
    assert!(cases > bytes.len() / 11);
    let missing = Trajectory::read_npz(&dir.path().join("nope.npz")).unwrap_err();
    assert!(missing.to_string().contains("nope.npz"));
}

/// Writes `t`, then rewrites the archive without array `drop`; returns the open writer.
fn write_without(path: &Path, t: &Trajectory, drop: &str) -> zip::ZipWriter<File> {
    t.write_arrays(path).unwrap();
    let src = std::fs::read(path).unwrap();
    let mut zin = zip::ZipArchive::new(Cursor::new(src)).unwrap();
    let mut zout = zip::ZipWriter::new(File::create(path).unwrap());
    for i in 0..zin.len() {
        let entry = zin.by_index(i).unwrap();
        if entry.name() != format!("{drop}.npy") {
            zout.raw_copy_file(entry).unwrap();
        }
    }
    zout
}

#[test]
fn trajectory_wrong_or_missing_array_names_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("odd.npz");
    let t = sample();
    for name in ["positions", "step_seconds", "meta"] {
        // Replace the array by a float32 vector.
        let mut zout = write_without(&path, &t, name);
        let mut npy = Vec::new();
        let mut w = npyz::WriteOptions::<f32>::new()
            .default_dtype()
            .shape(&[2])
            .writer(&mut npy)
            .begin_nd()
            .unwrap();
        w.extend([1.0f32, 2.0]).unwrap();
        w.finish().unwrap();
        zout.start_file(format!("{name}.npy"), entry_options()).unwrap();
        io::Write::write_all(&mut zout, &npy).unwrap();
        zout.finish().unwrap();
        let e = Trajectory::read_npz(&path).unwrap_err();
        assert_eq!(e.location, crate::Location::Field(name.into()), "{e}");
        assert!(e.to_string().contains("odd.npz"), "{e}");
    }

    write_without(&path, &t, "energies").finish().unwrap();
    let e = Trajectory::read_npz(&path).unwrap_err();
    assert_eq!(e.location, crate::Location::Field("energies".into()));
    assert!(e.message.contains("missing"), "{e}");
}

#[test]
fn trajectory_npz_loads_in_numpy() {
    let has_numpy = Command::new("python3")
        .args(["-c", "import numpy"])
        .status()
        .is_ok_and(|s| s.success());
    if !has_numpy {
        eprintln!("SKIPPED trajectory_npz_loads_in_numpy: python3 with numpy not available");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("numpy.npz");
    let t = sample();
    t.write_npz(&path).unwrap();
    let script = r#"
import sys, numpy as np
d = np.load(sys.argv[1])
p = d["positions"]
assert p.shape == (4, 5, 3) and p.dtype == np.float64, (p.shape, p.dtype)
assert d["bc_signal"].shape == (4, 2)
assert d["energies"].shape == (4, 3)
assert list(d["energy_names"]) == ["inertia", "elastic", "gravity"]
assert d["newton_iterations"].dtype == np.uint32
assert list(d["newton_iterations"]) == [0, 3, 4, 2]
assert d["step_seconds"][2] == 2.25e-3
assert float(d["dt"]) == 1.0 / 60.0
assert str(d["scene"]) == "cloth-flag \u2603"
meta = dict(zip(d["meta"][:, 0], d["meta"][:, 1]))
assert meta == {"seed": "42", "split": "train", "note": ""}, meta
assert int(d["format_version"]) == 1
print(repr(p[2, 4, 1]), repr(d["energies"][3, 1]))
# The same arrays written by numpy itself, compressed, for the Rust reader.
np.savez_compressed(sys.argv[2], **{k: d[k] for k in d.files})
"#;
    let out = Command::new("python3")
        .arg("-c")
        .arg(script)
        .arg(&path)
        .arg(dir.path().join("from_numpy.npz"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "numpy check failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Python's repr of a float64 round-trips, so compare exactly.
    let stdout = String::from_utf8_lossy(&out.stdout);
    let values: Vec<f64> = stdout
        .split_whitespace()
        .map(|s| {
            s.trim_start_matches("np.float64(")
                .trim_end_matches(')')
                .parse()
                .unwrap()
        })
        .collect();
    assert_eq!(values, vec![t.positions[2][4 * 3 + 1], t.energies[3][1]]);
    let from_numpy = Trajectory::read_npz(&dir.path().join("from_numpy.npz")).unwrap();
    assert_eq!(from_numpy, t);
}

#[test]
fn a_trajectory_written_before_colliders_existed_still_loads() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.npz");
    let t = sample();
    // The archive of a file from before colliders: the same arrays without the three.
    t.write_arrays(&path).unwrap();
    let src = std::fs::read(&path).unwrap();
    let mut zin = zip::ZipArchive::new(Cursor::new(src)).unwrap();
    let mut zout = zip::ZipWriter::new(File::create(&path).unwrap());
    for i in 0..zin.len() {
        let entry = zin.by_index(i).unwrap();
        if !entry.name().starts_with("collider_") {
            zout.raw_copy_file(entry).unwrap();
        }
    }
    zout.finish().unwrap();
    let old = Trajectory::read_npz(&path).unwrap();
    assert_eq!(old.colliders, None);
    assert_eq!(Trajectory { colliders: None, ..t }, old);
}

#[test]
fn collider_arrays_of_the_wrong_shape_name_the_array() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad-colliders.npz");
    let mut t = sample();
    t.colliders.as_mut().unwrap().states[2].pop();
    let e = t.write_npz(&path).unwrap_err();
    assert!(e.to_string().contains("collider_states"), "{e}");
    let mut t = sample();
    t.colliders.as_mut().unwrap().shapes[1][0] = 9.0;
    assert!(t.validate().unwrap_err().starts_with("collider_shapes"));
    // A states array of another shape in the file.
    let t = sample();
    let mut zout = write_without(&path, &t, "collider_states");
    let mut npy = Vec::new();
    let mut w = npyz::WriteOptions::<f64>::new()
        .default_dtype()
        .shape(&[4, 2, 11])
        .writer(&mut npy)
        .begin_nd()
        .unwrap();
    w.extend(vec![0.0; 88]).unwrap();
    w.finish().unwrap();
    zout.start_file("collider_states.npy", entry_options()).unwrap();
    io::Write::write_all(&mut zout, &npy).unwrap();
    zout.finish().unwrap();
    let e = Trajectory::read_npz(&path).unwrap_err();
    assert_eq!(e.location, crate::Location::Field("collider_states".into()), "{e}");
}
