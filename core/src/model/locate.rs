//! Where the model sets are, wherever a binary runs. A set named on the command line,
//! in the config file or in `SPWI_MODELS_DIR` is taken as given; otherwise the sets
//! folder is looked for in the current directory, beside the executable, in an
//! installed data directory and in the source tree the binary was built from, and an
//! error lists every place it looked.

use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

/// The set a daemon runs when none is named.
pub const DEFAULT_SET: &str = "default";

/// Where a folder of model sets is looked for, in order: `./models`, `models` beside
/// the executable, `../share/spwi/models` from it (an install prefix),
/// `/usr/local/share/spwi/models`, `/usr/share/spwi/models`, `/opt/spwi/models` (the
/// container image), and the `models` folder of the source tree this was built from.
pub fn candidates() -> Vec<PathBuf> {
    let mut places = vec![PathBuf::from("models")];
    if let Some(dir) = std::env::current_exe().ok().and_then(|e| e.parent().map(Path::to_owned)) {
        places.push(dir.join("models"));
        places.push(dir.join("../share/spwi/models"));
    }
    for installed in ["/usr/local/share/spwi/models", "/usr/share/spwi/models", "/opt/spwi/models"] {
        places.push(PathBuf::from(installed));
    }
    places.push(Path::new(env!("CARGO_MANIFEST_DIR")).join("../models"));
    places
}

/// The first folder of [`candidates`] that holds the set `name` (its `manifest.json`).
pub fn sets_folder(name: &str) -> Result<PathBuf> {
    let places = candidates();
    if let Some(found) = places.iter().find(|p| p.join(name).join("manifest.json").is_file()) {
        return Ok(found.clone());
    }
    let looked: Vec<String> = places.iter().map(|p| format!("  {}", p.join(name).display())).collect();
    bail!(
        "no model set {name:?} found; looked for {name}/manifest.json in:\n{}\nname one with --models DIR (or \
         SPWI_MODELS_DIR, or models.dir in the config file), or copy the repository's models/ folder beside \
         the executable",
        looked.join("\n")
    )
}

/// The set to load: `named` as given, or else the set `default_name` where
/// [`sets_folder`] finds it.
pub fn model_set(named: Option<&Path>, default_name: &str) -> Result<PathBuf> {
    match named {
        Some(dir) => Ok(dir.to_owned()),
        None => Ok(sets_folder(default_name)?.join(default_name)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_source_tree_is_a_last_resort_and_a_missing_set_names_every_place() {
        let found = sets_folder(DEFAULT_SET).unwrap();
        assert!(found.join("default/manifest.json").is_file());
        let e = sets_folder("no-such-set").unwrap_err().to_string();
        assert!(e.contains("no-such-set/manifest.json") && e.contains("--models DIR"), "{e}");
        for p in candidates() {
            assert!(e.contains(&p.join("no-such-set").display().to_string()), "{e} lacks {}", p.display());
        }
        let named = Path::new("/somewhere/else");
        assert_eq!(model_set(Some(named), DEFAULT_SET).unwrap(), named);
    }
}
