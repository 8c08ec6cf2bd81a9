//! mochi codegen: freezes a trained artifact (`SCENE.mochi`) into a Rust module of `static`
//! arrays and a [`mochi_runtime::Model`] describing them, for the no_std runtime.
//!
//! From a user crate's `build.rs` (with `mochi-codegen` as a build dependency):
//!
//! ```ignore
//! fn main() {
//!     mochi_codegen::build_rs("model/beam.mochi", "beam.rs").unwrap();
//! }
//! ```
//!
//! and in the crate: `include!(concat!(env!("OUT_DIR"), "/beam.rs"));`, which defines `MODEL`,
//! the sizes (`LATENT`, `SIGNAL`, `HIDDEN`, `STATE_LEN`, ...) and `type Instance`.
//!
//! The weight storage (`f32`, `f16`, int8 with per-row scales) is chosen with [`Options`]
//! ([`build_rs_with`], `mochi codegen --weights`); `mochi eval --storage` measures what each
//! costs in accuracy.
//!
//! The output is deterministic (same artifact, same bytes), compiles without warnings, and is
//! rustfmt-clean: the long literal arrays carry `#[rustfmt::skip]` and are wrapped at 100
//! columns.

use std::fmt::{self, Write as _};
use std::path::{Path, PathBuf};

pub mod quantize;

use mochi_runtime::{FieldValue, Handle, Layer, LoadError, Model, ModelError, OwnedModel, ValidModel, WeightFormat};

pub use quantize::{format_name, parse_format, Quantized};

/// What to generate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Options {
    /// How the decoder's weights are stored.
    pub decoder: WeightFormat,
    /// How the integrator's weights are stored.
    pub integrator: WeightFormat,
}

impl Options {
    /// The storage called `format` (`--weights`): both networks in `format`, except that int8
    /// keeps the integrator in `f16`. The integrator's rounding feeds back into every later
    /// step: with int8 weights the shipped beam drifts 22% of the diagonal from the `f32`
    /// rollout over 1,000 frames, with an `f16` integrator 0.25% (`mochi eval`, "Weight
    /// storage"); the decoder holds nearly all the weights, so the size is almost the same.
    pub fn weights(format: WeightFormat) -> Self {
        Options {
            decoder: format,
            integrator: match format {
                WeightFormat::Int8 => WeightFormat::F16,
                other => other,
            },
        }
    }
}

/// Version of the artifact format this code generator reads (the runtime's).
pub use mochi_runtime::ARTIFACT_VERSION;

/// Why code could not be generated.
#[derive(Debug)]
pub enum CodegenError {
    /// The artifact could not be read or written.
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        error: std::io::Error,
    },
    /// The artifact was refused.
    Artifact {
        /// The file (or the name given to [`generate`]).
        path: PathBuf,
        /// Why.
        error: LoadError,
    },
    /// The model is not valid in the chosen weight format (e.g. a weight beyond `f16`'s range).
    Model {
        /// The artifact.
        path: PathBuf,
        /// The format.
        format: WeightFormat,
        /// Why.
        error: ModelError,
    },
    /// `MOCHI_WEIGHTS` names no weight storage.
    Weights(String),
    /// `build_rs` ran outside a build script (`OUT_DIR` is not set).
    NoOutDir,
}

impl fmt::Display for CodegenError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CodegenError::Io { path, error } => write!(f, "{}: {error}", path.display()),
            CodegenError::Artifact { path, error } => write!(f, "{}: {error}", path.display()),
            CodegenError::Model { path, format, error } => {
                write!(f, "{}: with {} weights: {error}", path.display(), format_name(*format))
            }
            CodegenError::Weights(value) => write!(f, "MOCHI_WEIGHTS=`{value}` is not one of f32, f16, int8"),
            CodegenError::NoOutDir => write!(f, "OUT_DIR is not set: call build_rs from a build script"),
        }
    }
}

impl std::error::Error for CodegenError {}

/// Rust source for the artifact in `bytes` with `f32` weights; `name` (the artifact's file
/// name) goes into the header comment.
pub fn generate(bytes: &[u8], name: &str) -> Result<String, CodegenError> {
    generate_with(bytes, name, &Options::default())
}

/// Rust source for the artifact in `bytes` with the given options.
pub fn generate_with(bytes: &[u8], name: &str, options: &Options) -> Result<String, CodegenError> {
    let mut storage = OwnedModel::default();
    let model = storage.load(bytes).map_err(|error| CodegenError::Artifact {
        path: PathBuf::from(name),
        error,
    })?;
    let base = model.model();
    let quantized = Quantized::split(base, options.decoder, options.integrator);
    let stored = quantized.model(base);
    ValidModel::new(stored).map_err(|error| CodegenError::Model {
        path: PathBuf::from(name),
        format: options.decoder,
        error,
    })?;
    Ok(emit(&stored, mochi_runtime::artifact::wide_params_len(base), name))
}

/// Reads the artifact at `artifact`, writes its module (`f32` weights) to `out` (only when the
/// text changed, so builds that depend on it are not redone for nothing).
pub fn generate_file(artifact: &Path, out: &Path) -> Result<(), CodegenError> {
    generate_file_with(artifact, out, &Options::default())
}

/// [`generate_file`] with the given options.
pub fn generate_file_with(artifact: &Path, out: &Path, options: &Options) -> Result<(), CodegenError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |error| CodegenError::Io { path, error }
    };
    let bytes = std::fs::read(artifact).map_err(io(artifact))?;
    let name = artifact
        .file_name()
        .map_or_else(|| artifact.display().to_string(), |n| n.to_string_lossy().into_owned());
    let source = generate_with(&bytes, &name, options).map_err(|e| match e {
        CodegenError::Artifact { error, .. } => CodegenError::Artifact {
            path: artifact.to_path_buf(),
            error,
        },
        CodegenError::Model { format, error, .. } => CodegenError::Model {
            path: artifact.to_path_buf(),
            format,
            error,
        },
        other => other,
    })?;
    if std::fs::read_to_string(out).ok().as_deref() != Some(source.as_str()) {
        std::fs::write(out, source).map_err(io(out))?;
    }
    Ok(())
}

/// For build scripts: generates `OUT_DIR/out_name` from `artifact` (relative to the crate,
/// `f32` weights) and asks Cargo to rerun when the artifact changes.
pub fn build_rs(artifact: impl AsRef<Path>, out_name: &str) -> Result<(), CodegenError> {
    build_rs_with(artifact, out_name, &Options::default())
}

/// For build scripts that let whoever builds pick the model: generates `OUT_DIR/out_name`
/// from the artifact named by the environment variable `MOCHI_ARTIFACT` (else
/// `default_artifact`) with the weight storage `MOCHI_WEIGHTS` (`f32`, `f16` or `int8`;
/// default `f32`), and asks Cargo to rerun when either changes. Returns the artifact and the
/// storage's name.
pub fn build_rs_from_env(
    default_artifact: impl AsRef<Path>,
    out_name: &str,
) -> Result<(PathBuf, &'static str), CodegenError> {
    println!("cargo:rerun-if-env-changed=MOCHI_ARTIFACT");
    println!("cargo:rerun-if-env-changed=MOCHI_WEIGHTS");
    let artifact =
        std::env::var_os("MOCHI_ARTIFACT").map_or_else(|| default_artifact.as_ref().to_path_buf(), PathBuf::from);
    let weights = std::env::var("MOCHI_WEIGHTS").unwrap_or_else(|_| "f32".into());
    let format = parse_format(&weights).ok_or(CodegenError::Weights(weights))?;
    build_rs_with(&artifact, out_name, &Options::weights(format))?;
    Ok((artifact, format_name(format)))
}

/// [`build_rs`] with the given options.
pub fn build_rs_with(artifact: impl AsRef<Path>, out_name: &str, options: &Options) -> Result<(), CodegenError> {
    let out_dir = std::env::var_os("OUT_DIR").ok_or(CodegenError::NoOutDir)?;
    let artifact = artifact.as_ref();
    println!("cargo:rerun-if-changed={}", artifact.display());
    generate_file_with(artifact, &Path::new(&out_dir).join(out_name), options)
}

/// Writes the module for a validated model; `artifact_params` is the length of the artifact's
/// own (`f32`) parameter pool, the capacity loading it from bytes needs. The pools' statics and
/// the `MODEL` literal are written from the runtime's field list, [`Model::fields`].
fn emit(m: &Model, artifact_params: usize, name: &str) -> String {
    let mut s = String::new();
    let sizes: [(&str, &str, usize); 16] = [
        ("LATENT", "Latent size.", m.latent as usize),
        (
            "SIGNAL",
            "Boundary-condition numbers per frame (12 per handle).",
            m.bc_len as usize,
        ),
        (
            "HANDLES",
            "Handles (one `HandleMotion` each per step).",
            m.handles.len(),
        ),
        ("HIDDEN", "Widest hidden layer.", m.hidden()),
        ("DIM", "Coordinates per vertex.", m.dim()),
        ("NUM_VERTICES", "Vertices of the full mesh.", m.num_vertices as usize),
        (
            "STATE_LEN",
            "Length of a full decoded state (`decode_into`).",
            m.state_len(),
        ),
        (
            "SURFACE_LEN",
            "Length of a drawn-vertices state (`decode_surface_into`).",
            m.surface_len(),
        ),
        (
            "RENDER_LEN",
            "Length of the render mesh's positions and of its normals (`decode_render_into`; 0 without a render mesh).",
            m.render_len(),
        ),
        (
            "WEIGHT_BYTES",
            "Bytes of network weights, biases and scales.",
            m.weight_bytes(),
        ),
        ("PARAMS_LEN", "`f32` weights, biases and scales.", m.params.len()),
        ("HALVES_LEN", "Half-precision weights.", m.halves.len()),
        ("BYTES_LEN", "Int8 weights.", m.bytes.len()),
        (
            "ARTIFACT_PARAMS_LEN",
            "Weights and biases of the artifact (capacity for loading it from bytes).",
            artifact_params,
        ),
        (
            "FLOATS_LEN",
            "Other reals (capacity for loading from bytes).",
            m.floats.len(),
        ),
        (
            "INDICES_LEN",
            "Indices (capacity for loading from bytes).",
            m.indices.len(),
        ),
    ];
    let _ = writeln!(
        s,
        "// @generated by mochi-codegen {} from `{name}`. Do not edit.",
        env!("CARGO_PKG_VERSION")
    );
    let _ = writeln!(
        s,
        "// Artifact format {ARTIFACT_VERSION}; regenerate with `mochi codegen {name} -o FILE`."
    );
    for (ident, doc, value) in sizes {
        let _ = writeln!(s, "\n/// {doc}\npub const {ident}: usize = {value};");
    }
    let _ = writeln!(s, "\n/// Time step in seconds.\npub const DT: f32 = {:?};", m.dt);
    for (ident, layers) in [("DECODER_WEIGHTS", m.decoder), ("INTEGRATOR_WEIGHTS", m.integrator)] {
        let format = layers.first().map_or(WeightFormat::F32, |l| l.format);
        let _ = writeln!(
            s,
            "\n/// How the weights of this network are stored.\npub const {ident}: mochi_runtime::WeightFormat = mochi_runtime::WeightFormat::{format:?};"
        );
    }
    let _ = writeln!(s, "\n/// One simulated object of this model.");
    let _ = writeln!(
        s,
        "pub type Instance = mochi_runtime::Instance<LATENT, SIGNAL, HIDDEN>;"
    );
    let _ = writeln!(
        s,
        "\n/// Fixed-capacity storage that fits this model loaded from its artifact bytes."
    );
    let _ = writeln!(
        s,
        "pub type Loaded = mochi_runtime::LoadedModel<ARTIFACT_PARAMS_LEN, FLOATS_LEN, INDICES_LEN>;"
    );
    let fields = m.fields();
    for (field, value) in fields {
        let ident = static_name(field);
        match value {
            // The weights on a cache line (`mochi_runtime::aligned`), the other pools as arrays.
            FieldValue::F32s(v) if field == "params" => {
                aligned_array(&mut s, &ident, "f32", v.iter().map(|v| format!("{v:?}")))
            }
            FieldValue::F32s(v) => array(&mut s, &ident, "f32", v.iter().map(|v| format!("{v:?}"))),
            FieldValue::U16s(v) => array(&mut s, &ident, "u16", v.iter().map(|v| format!("{v:#06x}"))),
            FieldValue::I8s(v) => array(&mut s, &ident, "i8", v.iter().map(|v| v.to_string())),
            FieldValue::U32s(v) => array(&mut s, &ident, "u32", v.iter().map(|v| v.to_string())),
            FieldValue::Layers(v) => layers(&mut s, &ident, v),
            FieldValue::Handles(v) => handles(&mut s, &ident, v),
            FieldValue::U32(_) | FieldValue::F32(_) | FieldValue::Bool(_) | FieldValue::Span(_) => {}
        }
    }
    let _ = writeln!(
        s,
        "\n/// The model (validate once with `mochi_runtime::ValidModel::new(MODEL)`)."
    );
    let _ = writeln!(
        s,
        "pub static MODEL: mochi_runtime::Model<'static> = mochi_runtime::Model {{"
    );
    for (field, value) in fields {
        let value = match value {
            FieldValue::U32(v) => v.to_string(),
            FieldValue::F32(v) => format!("{v:?}"),
            FieldValue::Bool(v) => v.to_string(),
            FieldValue::Span(v) => span(v),
            FieldValue::F32s(_) if field == "params" => format!("&{}.0", static_name(field)),
            FieldValue::F32s(_)
            | FieldValue::U16s(_)
            | FieldValue::I8s(_)
            | FieldValue::U32s(_)
            | FieldValue::Layers(_)
            | FieldValue::Handles(_) => format!("&{}", static_name(field)),
        };
        let _ = writeln!(s, "    {field}: {value},");
    }
    let _ = writeln!(s, "}};");
    s
}

/// The `static` that holds the pool `field` of [`Model`] (`HANDLES` is the handle count).
fn static_name(field: &str) -> String {
    match field {
        "handles" => "HANDLE_LIST".into(),
        other => other.to_uppercase(),
    }
}

fn span(sp: mochi_runtime::Span) -> String {
    format!("mochi_runtime::Span {{ start: {}, len: {} }}", sp.start, sp.len)
}

fn layers(s: &mut String, ident: &str, layers: &[Layer]) {
    let _ = writeln!(
        s,
        "\n#[rustfmt::skip]\nstatic {ident}: [mochi_runtime::Layer; {}] = [",
        layers.len()
    );
    for l in layers {
        let _ = writeln!(
            s,
            "    mochi_runtime::Layer {{ rows: {}, cols: {}, format: mochi_runtime::WeightFormat::{:?}, weights: {}, bias: {}, scales: {} }},",
            l.rows, l.cols, l.format, l.weights, l.bias, l.scales
        );
    }
    let _ = writeln!(s, "];");
}

fn handles(s: &mut String, ident: &str, handles: &[Handle]) {
    let _ = writeln!(s, "\nstatic {ident}: [mochi_runtime::Handle; {}] = [", handles.len());
    for h in handles {
        let _ = writeln!(
            s,
            "    mochi_runtime::Handle {{\n        vertices: {},\n        reference: {},\n        pivot: [{:?}, {:?}, {:?}],\n    }},",
            span(h.vertices),
            span(h.reference),
            h.pivot[0],
            h.pivot[1],
            h.pivot[2]
        );
    }
    let _ = writeln!(s, "];");
}

/// [`array`] inside a `mochi_runtime::Aligned` (64-byte boundary).
fn aligned_array(s: &mut String, ident: &str, ty: &str, values: impl Iterator<Item = String>) {
    let _ = write!(
        s,
        "\n#[rustfmt::skip]\nstatic {ident}: mochi_runtime::Aligned<[{ty}; {ident}_LEN]> = mochi_runtime::Aligned("
    );
    array_values(s, values);
    let _ = writeln!(s, ");");
}

/// A `#[rustfmt::skip]` static array `[ty; IDENT_LEN]`, values wrapped at 100 columns.
fn array(s: &mut String, ident: &str, ty: &str, values: impl Iterator<Item = String>) {
    let _ = write!(s, "\n#[rustfmt::skip]\nstatic {ident}: [{ty}; {ident}_LEN] = ");
    array_values(s, values);
    let _ = writeln!(s, ";");
}

/// `[v, v, ...]` over lines of at most 100 columns (ends at the closing bracket).
fn array_values(s: &mut String, values: impl Iterator<Item = String>) {
    let _ = writeln!(s, "[");
    let mut line = String::from("   ");
    for v in values {
        if line.len() + v.len() + 2 > 100 {
            let _ = writeln!(s, "{}", line.trim_end());
            line = String::from("   ");
        }
        line.push(' ');
        line.push_str(&v);
        line.push(',');
    }
    if !line.trim().is_empty() {
        let _ = writeln!(s, "{}", line.trim_end());
    }
    s.push(']');
}
