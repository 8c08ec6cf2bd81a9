//! The `mochi` command-line tool: arguments in [`args`], what each subcommand does in
//! [`commands`].

mod args;
mod commands;

use anyhow::Result;
use clap::Parser;
use mochi_trainer::eval;
use mochi_trainer::eval::reduced_bench::ReducedBenchOptions;
use mochi_trainer::methods::reduced::rounding::Rounding;
use mochi_trainer::{shipped_scene_names, Recipe, Reporter};

use args::{Bench, Cli, Command};
use commands::{
    bench_reduced, bench_runtime, bench_sim, compare, demo, eval_models, eval_rates, make_dataset, mesh_asset,
    print_dataset_plan, simulate, train_scene, TrainFlags,
};

/// Reports on the terminal: stages and messages as lines on stdout, progress as bars.
struct Terminal;

impl Reporter for Terminal {
    fn stage(&self, name: &str) {
        println!("== {name}");
    }
    fn message(&self, text: &str) {
        println!("{text}");
    }
    fn bars(&self) -> bool {
        true
    }
}

fn main() {
    mochi_trainer::configure_threads();
    if let Err(e) = run(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Simulate {
            scene,
            frames,
            out,
            level,
            seed,
            obj,
            obj_every,
            png_frames,
        } => simulate(&scene, frames, out, level, seed, obj, obj_every, &png_frames),
        Command::Dataset {
            scene,
            out,
            sequences,
            shard,
            overwrite,
            plan,
        } => {
            let selection = match (sequences.is_empty(), shard) {
                (false, _) => mochi_sim::dataset::Selection::Names(sequences),
                (true, Some((index, count))) => mochi_sim::dataset::Selection::Shard { index, count },
                (true, None) => mochi_sim::dataset::Selection::All,
            };
            if plan {
                print_dataset_plan(&scene, &selection)
            } else {
                make_dataset(&scene, out, &selection, overwrite)
            }
        }
        Command::Mesh {
            asset,
            edge_length,
            vertices,
            out,
            accept_defects,
            threads,
        } => mesh_asset(asset, edge_length, vertices, out, accept_defects, threads),
        Command::Demo {
            scene,
            out,
            frames,
            retrain,
        } => demo(&scene, out, frames, retrain),
        Command::Train {
            scene,
            out,
            resume,
            latent,
            decoder,
            integrator_width,
            without_collider_inputs,
            frame_memory,
        } => train_scene(
            &scene,
            out,
            resume,
            &TrainFlags {
                latent,
                decoder: decoder.as_deref(),
                integrator_width,
                without_collider_inputs,
                frame_memory: frame_memory.as_deref(),
            },
        ),
        Command::Eval {
            artifacts,
            out,
            frames,
            rates,
            seconds,
            sequences,
            ..
        } if !rates.is_empty() => eval_rates(&artifacts, out, rates, seconds, frames, sequences),
        Command::Eval {
            artifacts,
            out,
            frames,
            accuracy_frames,
            adaptive,
            full_space_reference,
            ..
        } => eval_models(&artifacts, out, frames, accuracy_frames, adaptive, full_space_reference),
        Command::Compare {
            scene,
            model,
            reduced,
            peers,
            cases,
            cases_only,
            out,
            sequences,
            frames,
            matrix_frames,
            long_frames,
            conditions,
            max_substeps,
        } => compare(
            &scene,
            out,
            mochi_trainer::eval::compare::CompareOptions {
                model,
                reduced,
                peers,
                cases,
                cases_only,
                sequences,
                frames,
                matrix: (matrix_frames > 0).then_some(mochi_trainer::eval::compare::conditions::MatrixSpan {
                    frames: matrix_frames,
                    long_frames,
                }),
                conditions,
                max_substeps,
            },
        ),
        Command::Distill {
            artifact,
            out,
            modes,
            hidden,
            blocks,
            epochs,
            integrator,
            integrator_blocks,
            rounds,
            keep_decoder,
            strand_positions,
            frames,
        } => Ok(mochi_trainer::cli::distill::run(
            &artifact,
            &out,
            mochi_trainer::cli::distill::DistillChoice {
                decoder: (!keep_decoder).then_some(mochi_trainer::learn::distill::DistillShape {
                    modes,
                    hidden,
                    blocks,
                }),
                integrator: (integrator > 0).then_some(
                    mochi_trainer::learn::distill_integrator::IntegratorDistillShape {
                        hidden: integrator,
                        blocks: integrator_blocks,
                        rounds,
                    },
                ),
                frames,
                strand_positions,
            },
            epochs,
        )?),
        Command::Codegen { artifact, out, weights } => {
            mochi_codegen::generate_file_with(&artifact, &out, &mochi_codegen::Options::weights(weights))?;
            println!(
                "{} -> {} ({} weights)",
                artifact.display(),
                out.display(),
                mochi_codegen::format_name(weights)
            );
            Ok(())
        }
        Command::Upgrade { artifacts } => {
            for path in artifacts {
                let artifact = mochi_trainer::artifact::Artifact::read(&path)?;
                artifact.write(&path)?;
                println!("{}: format {}", path.display(), mochi_trainer::artifact::FORMAT_VERSION);
            }
            Ok(())
        }
        Command::Export {
            artifact,
            out,
            frames,
            level,
            seed,
            weights,
        } => commands::export(&artifact, out, frames, level, seed, weights),
        Command::ExportWeights {
            artifact,
            out,
            frames,
            weights,
        } => {
            let e = eval::network_export::export(&artifact, &out, frames, weights)?;
            println!(
                "{} -> {}: latent {}, signal {}, hidden {}, {} integrator and {} decoder layers, {} frames ({} clamped or held)",
                artifact.display(),
                out.display(),
                e.latent,
                e.signal,
                e.hidden,
                e.layers[0],
                e.layers[1],
                e.frames,
                e.departures
            );
            Ok(())
        }
        Command::Bench {
            what:
                Bench::Sim {
                    scenes,
                    frames,
                    per_step,
                    linear_solvers,
                    sweep,
                    values,
                    out,
                },
        } => bench_sim(scenes, frames, per_step, linear_solvers, sweep, values, out),
        Command::Bench {
            what:
                Bench::Runtime {
                    artifacts,
                    frames,
                    out,
                    weights,
                },
        } => bench_runtime(&artifacts, frames, out, &weights),
        Command::Bench {
            what:
                Bench::Reduced {
                    reduced,
                    frames,
                    cold,
                    stride,
                    single,
                    paper,
                    tolerance,
                    out,
                },
        } => {
            let options = ReducedBenchOptions {
                frames,
                cold,
                stride: stride as usize,
                rounding: if single { Rounding::Single } else { Rounding::Double },
                paper,
                tolerance,
            };
            bench_reduced(&reduced, &options, out)
        }
        Command::Scenes => {
            for name in shipped_scene_names() {
                let scene = Recipe::load(&name)?.scene;
                println!("{name:10} {}", scene.description);
            }
            Ok(())
        }
    }
}
