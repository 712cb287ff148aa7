//! A scratch folder for the tests that write files or run the binary: unique per call
//! (process id, a counter and a tag), removed on drop. Include with
//! `#[path = "common/scratch.rs"] mod scratch;`.
#![allow(dead_code)]

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

/// A scratch folder under the system temp dir, removed on drop.
pub struct Scratch(pub PathBuf);

impl Scratch {
    /// A fresh, empty folder named after `tag`.
    pub fn new(tag: &str) -> Scratch {
        static N: AtomicU64 = AtomicU64::new(0);
        let d = std::env::temp_dir().join(format!(
            "p2q_{tag}_{}_{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("test: create scratch dir");
        Scratch(d)
    }

    /// The path of `name` in the folder.
    pub fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    /// The path of `name` in the folder, as a string (for command lines).
    pub fn p(&self, name: &str) -> String {
        self.path(name).display().to_string()
    }

    /// Writes `bytes` to `name` in the folder; returns its path as a string.
    pub fn write(&self, name: &str, bytes: &[u8]) -> String {
        let p = self.path(name);
        std::fs::write(&p, bytes).expect("test: write input");
        p.display().to_string()
    }

    /// Names in the folder (files and folders, hidden ones included).
    pub fn entries(&self) -> BTreeSet<String> {
        std::fs::read_dir(&self.0)
            .expect("test: list scratch dir")
            .map(|e| e.expect("test: dir entry").file_name().to_string_lossy().into_owned())
            .collect()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
