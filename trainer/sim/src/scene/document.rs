//! Reading scene files: the text, and the TOML document that layers above the simulator take
//! their own tables out of before the rest is read as a [`Scene`].

use super::Scene;
use crate::error::InputError;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Reads a text file, naming it in the error.
pub fn read_text(path: &Path) -> Result<String, InputError> {
    std::fs::read_to_string(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))
}

/// A scene file parsed as TOML but not yet read as a [`Scene`]: layers above the simulator
/// take their own tables out of it (the trainer's `[latent]`) before the rest is read as the
/// scene, so one file describes the body and how to learn it while [`Scene`] knows only
/// the physics. Errors keep the line numbers of the original text.
pub struct SceneDocument<'a> {
    text: &'a str,
    path: PathBuf,
    root: toml::Spanned<toml::de::DeTable<'a>>,
}

impl<'a> SceneDocument<'a> {
    /// Parses `text` (the contents of `path`) as TOML.
    pub fn parse(text: &'a str, path: &Path) -> Result<Self, InputError> {
        let root = toml::de::DeTable::parse(text).map_err(|e| toml_error(text, path, &e))?;
        Ok(SceneDocument {
            text,
            path: path.to_path_buf(),
            root,
        })
    }

    /// Takes the top-level table `name` out of the document and reads it as a `T`; a missing
    /// table gives `T::default()`.
    pub fn take_section<T: serde::de::DeserializeOwned + Default>(&mut self, name: &str) -> Result<T, InputError> {
        let table = self.root.get_mut();
        let Some(key) = table.keys().find(|k| k.get_ref().as_ref() == name).cloned() else {
            return Ok(T::default());
        };
        let value = table
            .remove(&key)
            .unwrap_or_else(|| unreachable!("the key was just found"));
        T::deserialize(toml::de::ValueDeserializer::from(value)).map_err(|e| toml_error(self.text, &self.path, &e))
    }

    /// Reads what is left as the scene and validates it.
    pub fn into_scene(self) -> Result<Scene, InputError> {
        let mut scene = Scene::deserialize(toml::de::Deserializer::from(self.root))
            .map_err(|e| toml_error(self.text, &self.path, &e))?;
        scene.source = self.path;
        scene.validate()?;
        Ok(scene)
    }
}

/// A TOML error at its line of `text`.
fn toml_error(text: &str, path: &Path, e: &toml::de::Error) -> InputError {
    let line = e
        .span()
        .map_or(1, |s| text[..s.start.min(text.len())].matches('\n').count() + 1);
    InputError::line(path, line, e.message().to_string())
}
