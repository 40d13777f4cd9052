//! The site (DESIGN §17): the file named by `[site] file` (or `--site`), loaded
//! at start, validated by `--check-config`, and reloaded on request (a goal
//! request of kind `reload-site`, `wlnav site reload`).
//!
//! A reload reads and validates the whole file on the IPC task, never on the
//! tick: a valid site waits in the [`SiteSlot`] until the control thread swaps
//! it in at the next tick boundary (the goal check, the pilot and telemetry
//! together); any error leaves the old site in force and is the reply's text.
//! Never a half-loaded site: the file is read whole, parsed and indexed before
//! anything sees it.
//!
//! A `.json` file is a `wlnav-site-v1` file; a `.yaml` / `.yml` file is a
//! ROS / Nav2 `map_server` map (its image, a PGM, named in it and found
//! relative to it), imported as occupied-cell rectangles.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use control::site::nav2::{self, ImportOptions};
use control::site::{Site, SiteIndex};

/// Why a site file is not taken (the message names the file and what is wrong).
#[derive(Debug, thiserror::Error)]
pub enum SiteLoadError {
    #[error("site file {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("site file {path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

/// Largest file read (the site's own limit, [`control::site::MAX_FILE_BYTES`];
/// a map image may be larger: [`nav2::MAX_PIXELS`]).
fn read(path: &Path, limit: u64) -> Result<Vec<u8>, SiteLoadError> {
    let fail = |source| SiteLoadError::Read {
        path: path.to_path_buf(),
        source,
    };
    let len = std::fs::metadata(path).map_err(fail)?.len();
    if len > limit {
        return Err(SiteLoadError::Invalid {
            path: path.to_path_buf(),
            message: format!("{len} bytes, more than the limit of {limit}"),
        });
    }
    std::fs::read(path).map_err(fail)
}

/// Loads and validates the site file at `path` (module docs), then builds
/// its index.
pub fn load(path: &Path) -> Result<SiteIndex, SiteLoadError> {
    let invalid = |message: String| SiteLoadError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or_default()
        .to_ascii_lowercase();
    let site = match ext.as_str() {
        "yaml" | "yml" => {
            let text = read(path, 1 << 20)?;
            let text = String::from_utf8(text).map_err(|e| invalid(format!("not UTF-8: {e}")))?;
            let yaml = nav2::MapYaml::parse(&text).map_err(|e| invalid(e.to_string()))?;
            let image = path
                .parent()
                .unwrap_or_else(|| Path::new("."))
                .join(&yaml.image);
            let pgm = read(&image, nav2::MAX_PIXELS as u64 + 4096)?;
            let id = path
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or("map")
                .to_string();
            let opts = ImportOptions {
                id,
                version: 1,
                unknown_is_free: false,
            };
            nav2::import(&text, &pgm, &opts).map_err(|e| invalid(e.to_string()))?
        }
        _ => {
            let bytes = read(path, control::site::MAX_FILE_BYTES as u64)?;
            Site::parse(&bytes).map_err(|e| invalid(e.to_string()))?
        }
    };
    Ok(SiteIndex::new(site))
}

/// One line about a loaded site: id, version, hash, features, index memory.
pub fn describe(index: &SiteIndex) -> String {
    let s = index.site();
    format!(
        "site `{}` version {} hash {} ({} features, index {} KiB)",
        s.id(),
        s.version(),
        s.hash_hex(),
        s.features().len(),
        index.memory_bytes().div_ceil(1024)
    )
}

/// A reloaded site for the control thread: the index and its description
/// (formatted by the reload, so that the tick that swaps it in only logs it).
pub type PendingSite = (Arc<SiteIndex>, String);

/// The configured site file, a reloaded site waiting for the next tick, and
/// the site it replaced, handed back by the control thread so that the whole
/// old index is freed here (by the next reload, or with the slot), not on the
/// tick.
#[derive(Debug)]
pub struct SiteSlot {
    path: Option<PathBuf>,
    pending: Mutex<Option<PendingSite>>,
    retired: Mutex<Option<Arc<SiteIndex>>>,
}

impl SiteSlot {
    /// The slot of the site file `path` (`None`: the daemon has no site).
    pub fn new(path: Option<PathBuf>) -> Self {
        Self {
            path,
            pending: Mutex::new(None),
            retired: Mutex::new(None),
        }
    }

    /// Reads the configured file again. On success the new site waits for the
    /// next tick ([`SiteSlot::take`]) and its description is returned; on any
    /// error nothing changes. Frees the site the last swap retired. Refused
    /// while the daemon shuts down: no tick would put it in force.
    pub fn reload(&self, shutting_down: bool) -> Result<String, String> {
        if shutting_down {
            return Err("the daemon is shutting down".into());
        }
        let Some(path) = &self.path else {
            return Err("the daemon has no site file (`[site] file` / `--site`)".into());
        };
        drop(
            self.retired
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .take(),
        );
        let index = load(path).map_err(|e| e.to_string())?;
        let text = describe(&index);
        *self.pending.lock().unwrap_or_else(|p| p.into_inner()) =
            Some((Arc::new(index), text.clone()));
        Ok(text)
    }

    /// A reloaded site not yet in force, if any (the control thread, at a
    /// tick boundary). A `try_lock`: a reload being stored is taken next tick.
    pub fn take(&self) -> Option<PendingSite> {
        self.pending.try_lock().ok().and_then(|mut p| p.take())
    }

    /// Takes the site a swap replaced (the control thread): it is freed off
    /// the tick. Gives it back when the slot is busy (a reload is freeing the
    /// last one): the caller keeps it and retires it at a later tick.
    pub fn retire(&self, old: Arc<SiteIndex>) -> Result<(), Arc<SiteIndex>> {
        match self.retired.try_lock() {
            Ok(mut r) if r.is_none() => {
                *r = Some(old);
                Ok(())
            }
            _ => Err(old),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    const SITE: &str = r#"{"format": "wlnav-site-v1", "id": "pad", "version": 3,
        "bounds": [[-10, -10], [10, -10], [10, 10], [-10, 10]],
        "obstacles": [{"id": "pile-1", "circle": [3, 3, 1]}]}"#;

    #[test]
    fn a_reload_waits_for_the_tick_and_an_error_keeps_nothing_pending() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "pad.json", SITE);
        let slot = SiteSlot::new(Some(path.clone()));
        assert!(slot.take().is_none());
        let text = slot.reload(false).unwrap();
        assert!(text.starts_with("site `pad` version 3 hash "), "{text}");
        let (taken, described) = slot.take().unwrap();
        assert_eq!(described, text);
        assert_eq!(taken.site().features().len(), 1);
        assert!(slot.take().is_none());
        // The site a swap replaces is handed back, freed by the next reload
        // (not by the control thread), one at a time.
        let old = Arc::new(load(&path).unwrap());
        let weak = Arc::downgrade(&old);
        slot.retire(old).unwrap();
        let second = Arc::new(load(&path).unwrap());
        let second = slot.retire(second).expect_err("one retired site at a time");
        assert!(weak.upgrade().is_some(), "freed before a reload");
        slot.reload(false).unwrap();
        assert!(
            weak.upgrade().is_none(),
            "the reload frees the retired site"
        );
        slot.retire(second).unwrap();
        slot.take().unwrap();
        // A broken file: the error names the file, the feature and what is wrong.
        write(
            dir.path(),
            "pad.json",
            &SITE.replace(r#""circle": [3, 3, 1]"#, r#""circle": [3, 3, -1]"#),
        );
        let e = slot.reload(false).unwrap_err();
        assert!(e.contains("pad.json") && e.contains("pile-1"), "{e}");
        assert!(slot.take().is_none());
        std::fs::remove_file(&path).unwrap();
        assert!(slot.reload(false).unwrap_err().contains("pad.json"));
        assert!(SiteSlot::new(None)
            .reload(false)
            .unwrap_err()
            .contains("no site file"));
        // Shutting down: refused, nothing read or pending.
        assert!(slot.reload(true).unwrap_err().contains("shutting down"));
        assert!(slot.take().is_none());
    }

    #[test]
    fn a_nav2_map_is_imported_with_its_image_beside_it() {
        let dir = tempfile::tempdir().unwrap();
        // 4 × 2 pixels at 0.5 m: one occupied (black) column at x = 1.0–1.5.
        let mut pgm = b"P5\n4 2\n255\n".to_vec();
        pgm.extend_from_slice(&[254, 254, 0, 254, 254, 254, 0, 254]);
        std::fs::write(dir.path().join("yard.pgm"), &pgm).unwrap();
        let yaml = write(
            dir.path(),
            "yard.yaml",
            "image: yard.pgm\nresolution: 0.5\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n\
             occupied_thresh: 0.65\nfree_thresh: 0.196\n",
        );
        let index = load(&yaml).unwrap();
        assert_eq!(index.site().id(), "yard");
        assert!(!index.site().features().is_empty());
        std::fs::remove_file(dir.path().join("yard.pgm")).unwrap();
        let e = load(&yaml).unwrap_err().to_string();
        assert!(e.contains("yard.pgm"), "{e}");
    }
}
