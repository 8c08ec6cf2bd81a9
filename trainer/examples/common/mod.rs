//! What the subspace diagnostics (`pca_rollout`, `sensitivity`) share: their arguments
//! `SCENE K DATASET_DIR [FRAMES]` and the PCA subspace of the scene's training frames.

use mochi_trainer::dataset::{self, Split};
use mochi_trainer::encoding::Encoding;
use mochi_trainer::latent::encode_sequences;
use mochi_trainer::pca::Pca;
use mochi_trainer::scene::{Problem, Scene};
use std::path::PathBuf;

/// Reads `SCENE K DATASET_DIR [FRAMES]` (300 frames by default) from the command line of
/// `example`, generates the dataset in `DATASET_DIR` if missing and fits the subspace.
/// Returns the built scene, its boundary-relative encoding, the subspace, `K`, the dataset
/// directory and the frames of each test sequence to roll out.
pub fn subspace_from_args(example: &str) -> anyhow::Result<(Problem, Encoding, Pca, usize, PathBuf, usize)> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        anyhow::bail!("usage: {example} SCENE K DATASET_DIR [FRAMES]");
    }
    let mut problem = Scene::load(&args[1])?.build()?;
    let k: usize = args[2].parse()?;
    let dir = PathBuf::from(&args[3]);
    let frames: usize = args.get(4).map_or(Ok(300), |s| s.parse())?;
    dataset::generate(&mut problem, &dir, None, false, true)?;
    let encoding = Encoding::new(&problem)?;
    let train = dataset::load(&problem, &dir, Split::Train)?
        .into_iter()
        .map(|(_, t)| t)
        .collect();
    let encoded: Vec<Vec<f64>> = encode_sequences(&encoding, train)?
        .into_iter()
        .flat_map(|s| s.encoded)
        .collect();
    let pca = Pca::fit(&encoded, k)?;
    Ok((problem, encoding, pca, k, dir, frames))
}
