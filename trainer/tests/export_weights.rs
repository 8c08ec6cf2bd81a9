//! `mochi export-weights`: the archive holds the runtime's networks bit for bit, and what it
//! holds is enough to recompute the runtime's rollout (an independent f64 implementation of
//! the documented math lands on the runtime's latents and positions).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use mochi_codegen::quantize::weights_f32;
use mochi_codegen::{Options, Quantized};
use mochi_runtime::{OwnedModel, ValidModel, WeightFormat};

fn artifact(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/artifacts")
        .join(name)
}

fn export(artifact: &Path, out: &Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_mochi"))
        .args([
            "export-weights",
            artifact.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .args(args)
        .output()
        .expect("mochi runs")
}

/// Every array of an archive as `f64`s with its shape.
struct Archive(HashMap<String, (Vec<u64>, Vec<f64>)>);

impl Archive {
    fn read(path: &Path) -> Self {
        let mut npz = npyz::npz::NpzArchive::open(path).unwrap();
        let names: Vec<String> = npz.array_names().map(str::to_string).collect();
        let mut arrays = HashMap::new();
        for name in names {
            let npy = npz.by_name(&name).unwrap().unwrap();
            let shape = npy.shape().to_vec();
            let values = match npy.dtype().descr().trim_matches('\'') {
                "<f4" => npy.into_vec::<f32>().unwrap().into_iter().map(f64::from).collect(),
                "<u4" => npy.into_vec::<u32>().unwrap().into_iter().map(f64::from).collect(),
                "|u1" => npy.into_vec::<u8>().unwrap().into_iter().map(f64::from).collect(),
                _ => Vec::new(), // strings
            };
            arrays.insert(name, (shape, values));
        }
        Archive(arrays)
    }
    fn get(&self, name: &str) -> &[f64] {
        &self.0.get(name).unwrap_or_else(|| panic!("no array `{name}`")).1
    }
    fn shape(&self, name: &str) -> &[u64] {
        &self.0[name].0
    }
    fn scalar(&self, name: &str) -> usize {
        self.get(name)[0] as usize
    }
    fn has(&self, name: &str) -> bool {
        self.0.contains_key(name)
    }
}

/// One dense layer read back: `b + s * (W x)`.
struct Dense {
    rows: usize,
    cols: usize,
    w: Vec<f64>,
    b: Vec<f64>,
    scale: Option<Vec<f64>>,
}

impl Dense {
    fn apply(&self, x: &[f64]) -> Vec<f64> {
        (0..self.rows)
            .map(|r| {
                let dot: f64 = (0..self.cols).map(|c| self.w[r * self.cols + c] * x[c]).sum();
                self.b[r] + self.scale.as_ref().map_or(1.0, |s| s[r]) * dot
            })
            .collect()
    }
}

fn layers(a: &Archive, net: &str) -> Vec<Dense> {
    let shapes = a.get(&format!("{net}_layers"));
    shapes
        .chunks(2)
        .enumerate()
        .map(|(i, rc)| Dense {
            rows: rc[0] as usize,
            cols: rc[1] as usize,
            w: a.get(&format!("{net}_{i}_w")).to_vec(),
            b: a.get(&format!("{net}_{i}_b")).to_vec(),
            scale: a
                .has(&format!("{net}_{i}_scale"))
                .then(|| a.get(&format!("{net}_{i}_scale")).to_vec()),
        })
        .collect()
}

fn swish(v: f64) -> f64 {
    v / (1.0 + (-v).exp())
}

/// `h = input(x); h += outer(swish(inner(h))); y = output(swish(h))`.
fn forward(net: &[Dense], x: &[f64]) -> Vec<f64> {
    let mut h = net[0].apply(x);
    for pair in net[1..net.len() - 1].chunks(2) {
        let a: Vec<f64> = pair[0].apply(&h).into_iter().map(swish).collect();
        h.iter_mut().zip(pair[1].apply(&a)).for_each(|(h, r)| *h += r);
    }
    let h: Vec<f64> = h.into_iter().map(swish).collect();
    net[net.len() - 1].apply(&h)
}

/// Rodrigues' formula, row-major.
fn rotation(v: &[f64]) -> [[f64; 3]; 3] {
    let angle = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if angle <= f64::from(f32::EPSILON) {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    let (x, y, z) = (v[0] / angle, v[1] / angle, v[2] / angle);
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
        [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
        [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
    ]
}

fn turn(r: &[[f64; 3]; 3], p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2])
}

/// Replays the archive's script with its networks (one handle, origin at the handle
/// centroid, 3D); returns the largest latent difference from the runtime's and the largest
/// vertex distance / diagonal from its kept positions.
fn replay(a: &Archive) -> (f64, f64) {
    let (k, s, n) = (a.scalar("latent"), a.scalar("signal"), a.scalar("num_vertices"));
    assert_eq!(
        (a.scalar("dim"), a.get("handle_counts").len()),
        (3, 1),
        "the replay covers this case"
    );
    assert!(a.get("root_slots").is_empty());
    let (integrator, decoder) = (layers(a, "integrator"), layers(a, "decoder"));
    let (lo, hi, margin) = (a.get("latent_min"), a.get("latent_max"), a.get("range_margin")[0]);
    let (signals, latents) = (a.get("script_signal"), a.get("runtime_latent"));
    let kept: Vec<usize> = a.get("runtime_frames").iter().map(|&f| f as usize).collect();
    let (pivot, reference) = (a.get("handle_pivot"), a.get("handle_reference"));
    let pivot = [pivot[0], pivot[1], pivot[2]];
    let diagonal = a.get("diagonal")[0];
    let mut z = a.get("initial_latent").to_vec();
    let mut z_prev = z.clone();
    let (mut p1, mut p2) = (vec![0.0; s], vec![0.0; s]);
    let (mut latent_gap, mut position_gap) = (0.0f64, 0.0f64);
    for (t, p) in signals.chunks(s).enumerate() {
        let x: Vec<f64> = [&z[..], &z_prev, p, &p1, &p2].concat();
        let mut next: Vec<f64> = z.iter().zip(forward(&integrator, &x)).map(|(z, d)| z + d).collect();
        for (i, v) in next.iter_mut().enumerate() {
            let w = margin * (hi[i] - lo[i]);
            *v = v.clamp(lo[i] - w, hi[i] + w);
        }
        for (got, want) in next.iter().zip(&latents[t * k..(t + 1) * k]) {
            latent_gap = latent_gap.max((got - want).abs());
        }
        z_prev = std::mem::replace(&mut z, next);
        p2 = std::mem::replace(&mut p1, p.to_vec());
        let Some(kept_at) = kept.iter().position(|&f| f == t + 1) else {
            continue;
        };
        let r = rotation(&p[9..12]);
        let targets: Vec<[f64; 3]> = reference
            .chunks(3)
            .map(|q| {
                let turned = turn(&r, std::array::from_fn(|i| q[i] - pivot[i]));
                std::array::from_fn(|i| pivot[i] + p[6 + i] + turned[i])
            })
            .collect();
        let centroid: [f64; 3] =
            std::array::from_fn(|i| targets.iter().map(|t| t[i]).sum::<f64>() / targets.len() as f64);
        let mut positions = vec![[0.0; 3]; n];
        let q = forward(&decoder, &z);
        for (&v, q) in a.get("free_vertices").iter().zip(q.chunks(3)) {
            let world = turn(&r, [q[0], q[1], q[2]]);
            positions[v as usize] = std::array::from_fn(|i| world[i] + centroid[i]);
        }
        for (&v, target) in a.get("handle_vertices").iter().zip(&targets) {
            positions[v as usize] = *target;
        }
        let runtime = &a.get("runtime_positions")[kept_at * 3 * n..(kept_at + 1) * 3 * n];
        for (mine, theirs) in positions.iter().zip(runtime.chunks(3)) {
            let d = (0..3).map(|i| (mine[i] - theirs[i]).powi(2)).sum::<f64>().sqrt();
            position_gap = position_gap.max(d / diagonal);
        }
    }
    (latent_gap, position_gap)
}

#[test]
fn export_holds_the_runtime_networks_and_reproduces_its_rollout() {
    let dir = tempfile::tempdir().unwrap();
    let path = artifact("tiny.mochi");
    let bytes = std::fs::read(&path).unwrap();
    let mut storage = OwnedModel::default();
    let base = storage.load(&bytes).unwrap();
    for (weights, name, limit) in [(WeightFormat::F32, "f32", 1e-5), (WeightFormat::Int8, "int8", 1e-5)] {
        let out = dir.path().join(format!("tiny-{name}.npz"));
        let run = export(&path, &out, &["--frames", "120", "--weights", name]);
        assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
        let a = Archive::read(&out);
        let options = Options::weights(weights);
        let stored = Quantized::split(base.model(), options.decoder, options.integrator);
        let model = ValidModel::new(stored.model(base.model())).unwrap();
        let m = model.model();
        assert_eq!(a.scalar("latent"), m.latent as usize);
        assert_eq!(a.scalar("hidden"), m.hidden());
        assert_eq!(a.shape("script_signal"), [120, u64::from(m.bc_len)]);
        assert_eq!(a.shape("runtime_latent"), [120, u64::from(m.latent)]);
        assert_eq!(a.get("runtime_frames"), [1.0, 10.0, 100.0, 120.0]);
        assert_eq!(a.shape("runtime_positions"), [4, u64::from(m.num_vertices), 3]);
        // Every layer: shape, and the weights the runtime multiplies by (scale times the
        // stored integers for int8) bit for bit.
        for (net, layers) in [("integrator", m.integrator), ("decoder", m.decoder)] {
            assert_eq!(a.shape(&format!("{net}_layers")), [layers.len() as u64, 2]);
            for (i, layer) in layers.iter().enumerate() {
                let w = a.get(&format!("{net}_{i}_w"));
                assert_eq!(
                    a.shape(&format!("{net}_{i}_w")),
                    [u64::from(layer.rows), u64::from(layer.cols)]
                );
                let scale = format!("{net}_{i}_scale");
                assert_eq!(a.has(&scale), layer.format == WeightFormat::Int8, "{scale}");
                let effective: Vec<f32> = match layer.format {
                    WeightFormat::Int8 => w
                        .chunks(layer.cols as usize)
                        .zip(a.get(&scale))
                        .flat_map(|(row, &s)| row.iter().map(move |&q| s as f32 * q as f32))
                        .collect(),
                    _ => w.iter().map(|&v| v as f32).collect(),
                };
                assert_eq!(effective, weights_f32(m, layer), "{net} layer {i} ({name})");
            }
        }
        let (latent_gap, position_gap) = replay(&a);
        assert!(latent_gap < limit, "{name}: latents differ by {latent_gap:e}");
        assert!(
            position_gap < limit,
            "{name}: positions differ by {position_gap:e} of the diagonal"
        );
    }
}

#[test]
fn bend_encoded_strands_are_exported_with_their_chains() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.npz");
    let run = export(&artifact("strands.mochi"), &out, &["--frames", "20"]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let a = Archive::read(&out);
    assert_eq!(a.scalar("bends"), 1);
    let bytes = std::fs::read(artifact("strands.mochi")).unwrap();
    let mut storage = OwnedModel::default();
    let model = storage.load(&bytes).unwrap();
    let m = model.model();
    let chains: Vec<_> = m.chains().collect();
    assert_eq!(a.shape("chain_parent"), [chains.len() as u64, 2]);
    let (mut slots, mut lengths) = (Vec::new(), Vec::new());
    for (i, c) in chains.iter().enumerate() {
        assert_eq!(a.get("chain_parent")[2 * i..2 * i + 2], c.parent.map(f64::from));
        assert_eq!(
            a.get("chain_rest_normal")[3 * i..3 * i + 3],
            c.rest_normal.map(f64::from)
        );
        assert_eq!(a.get("chain_count")[i], c.slots.len() as f64);
        slots.extend(c.slots.iter().map(|&v| f64::from(v)));
        lengths.extend(c.lengths.iter().map(|&v| f64::from(v)));
    }
    assert_eq!(a.get("chain_slots"), slots);
    assert_eq!(a.get("chain_lengths"), lengths);
    assert_eq!(slots.len(), m.free_vertices().len(), "every free vertex is on a strand");
    // Two numbers per free vertex come out of the decoder.
    let last = a.shape("decoder_layers")[0] as usize - 1;
    assert_eq!(a.shape(&format!("decoder_{last}_w"))[0] as usize, 2 * slots.len());
}
