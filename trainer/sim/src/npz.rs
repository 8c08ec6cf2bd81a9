//! Writing numpy `.npz` archives: uncompressed like `numpy.savez`, so large arrays cost no
//! compression time, and strings as fixed-width unicode arrays, so `numpy.load` opens every
//! archive without `allow_pickle`.

use std::fs::File;
use std::io::{self, BufWriter};
use std::path::Path;

use npyz::npz::NpzWriter;
use npyz::zip::{self, CompressionMethod};
use npyz::{DType, TypeStr, WriterBuilder};

/// An `.npz` archive being written; [`NpzOut::finish`] completes it.
pub struct NpzOut {
    npz: NpzWriter<BufWriter<File>>,
}

/// How every array is stored: uncompressed, with Zip64 entries for arrays of 2 GiB and more.
pub(crate) fn entry_options() -> zip::write::FileOptions {
    zip::write::FileOptions::default()
        .compression_method(CompressionMethod::Stored)
        .large_file(true)
}

impl NpzOut {
    /// Creates (or truncates) the archive at `path`.
    pub fn create(path: &Path) -> io::Result<Self> {
        Ok(NpzOut {
            npz: NpzWriter::create(path)?,
        })
    }

    /// Writes a numeric array `name` of `shape` (row-major) with the default dtype of `T`
    /// (little-endian); `data` must hold the product of `shape` elements.
    pub fn array<T: npyz::AutoSerialize>(
        &mut self,
        name: &str,
        shape: &[u64],
        data: impl IntoIterator<Item = T>,
    ) -> io::Result<()> {
        let mut writer = self
            .npz
            .array::<T>(name, entry_options())?
            .default_dtype()
            .shape(shape)
            .begin_nd()?;
        writer.extend(data)?;
        writer.finish()
    }

    /// Writes strings as a fixed-width unicode (`<U`) array `name` of `shape`.
    pub fn strings<'a>(
        &mut self,
        name: &str,
        shape: &[u64],
        strings: impl IntoIterator<Item = &'a str> + Clone,
    ) -> io::Result<()> {
        let width = strings
            .clone()
            .into_iter()
            .map(|s| s.chars().count())
            .max()
            .unwrap_or(0)
            .max(1);
        let type_str: TypeStr = format!("<U{width}")
            .parse()
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, format!("{e}")))?;
        let mut writer = self
            .npz
            .array::<str>(name, entry_options())?
            .dtype(DType::Plain(type_str))
            .shape(shape)
            .begin_nd()?;
        for s in strings {
            writer.push(s)?;
        }
        writer.finish()
    }

    /// Writes the archive's directory and flushes the file.
    pub fn finish(mut self) -> io::Result<()> {
        let mut file = self.npz.zip_writer().finish()?;
        io::Write::flush(&mut file)
    }
}
