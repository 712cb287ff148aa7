//! Checkpoints: the model's named tensors, a model-config blob and (optionally) the
//! training state, in one little-endian binary file protected by a checksum.
//!
//! Layout (all integers little-endian):
//! ```text
//! magic "P2QCKPT\0" (8) | version u32 | reserved u32 | total_len u64 (whole file)
//! config_len u64 | config bytes
//! n_tensors u64 | n × tensor
//! has_train u8 | [ epoch u64 | step u64 | rng 4×u64 | n_momentum u64 | n × tensor
//!                  | (has_train = 2 only) n_run u64 | n × (text key | text value) ]
//! checksum u64 = FNV-1a 64 of every preceding byte
//! tensor = name_len u32 | name (UTF-8) | rank u8 | rank × dim u64 | numel × f32
//! text = len u32 | UTF-8 bytes
//! ```
//! `has_train` is 0 (weights only), 1 (training state) or 2 (training state and the
//! run's record: what the training command needs to continue the same run). A state
//! with an empty record is written with flag 1, byte for byte as before the record
//! existed; a build older than the record refuses flag 2 with a message.
//! Loading checks, in order, the length, magic, version, declared length, checksum,
//! then parses with a bounds check before every read; any failure is an
//! `Error::Checkpoint` naming the file — never a panic. `save` writes atomically
//! (temporary file, then rename).

use crate::tensor::{ParamStore, Tensor};
use crate::{Error, Result};
use std::path::Path;

/// File magic.
pub const MAGIC: [u8; 8] = *b"P2QCKPT\0";
/// Format version written (and the only one read).
pub const VERSION: u32 = 1;
const HEADER_LEN: usize = 8 + 4 + 4 + 8;

/// Training state saved next to the weights so training resumes exactly.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainState {
    /// Epochs completed.
    pub epoch: u64,
    /// Optimiser steps taken.
    pub step: u64,
    /// `crate::rng::Rng::state()` of the training RNG.
    pub rng: [u64; 4],
    /// Momentum buffers by parameter name (`Sgd::buffers`).
    pub momentum: Vec<(String, Tensor)>,
    /// The run's record, as (key, value) text pairs in the order written: whatever the
    /// caller needs to continue the same run (the `train` command stores its options and
    /// a fingerprint of its data). Empty when none was stored; the library's `train`
    /// leaves it empty.
    pub run: Vec<(String, String)>,
}

/// Everything a checkpoint file holds.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    /// Opaque model configuration (e.g. the config struct serialised as text).
    pub config: Vec<u8>,
    /// Named tensors (parameters and buffers), in store order.
    pub tensors: Vec<(String, Tensor)>,
    /// Training state, if saved.
    pub train: Option<TrainState>,
}

/// FNV-1a, 64-bit.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = Fnv1a::new();
    h.write(bytes);
    h.finish()
}

/// FNV-1a, 64-bit, fed in pieces: the same value as [`fnv1a64`] of the pieces joined.
#[derive(Clone, Copy, Debug)]
pub struct Fnv1a(u64);

impl Fnv1a {
    /// The empty hash.
    pub fn new() -> Self {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }

    /// Feeds `bytes`.
    pub fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    /// The hash of everything fed so far.
    pub fn finish(&self) -> u64 {
        self.0
    }
}

impl Default for Fnv1a {
    fn default() -> Self {
        Fnv1a::new()
    }
}

fn put_text(out: &mut Vec<u8>, s: &str) {
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

fn put_tensor(out: &mut Vec<u8>, name: &str, t: &Tensor) {
    out.extend_from_slice(&(name.len() as u32).to_le_bytes());
    out.extend_from_slice(name.as_bytes());
    out.push(t.dims().len() as u8);
    for &d in t.dims() {
        out.extend_from_slice(&(d as u64).to_le_bytes());
    }
    if cfg!(target_endian = "little") {
        out.extend_from_slice(bytemuck::cast_slice::<f32, u8>(t.data()));
    } else {
        for v in t.data() {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
}

struct Reader<'a> {
    b: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    fn err(&self, msg: impl Into<String>) -> Error {
        Error::Checkpoint {
            path: self.path.to_path_buf(),
            msg: format!("{} (at byte {})", msg.into(), self.pos),
        }
    }
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        if n > self.b.len() - self.pos {
            return Err(self.err(format!("truncated while reading {what} ({n} bytes wanted)")));
        }
        let s = &self.b[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.take(1, what)?[0])
    }
    fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le(bytemuck::pod_read_unaligned(self.take(4, what)?)))
    }
    fn u64(&mut self, what: &str) -> Result<u64> {
        Ok(u64::from_le(bytemuck::pod_read_unaligned(self.take(8, what)?)))
    }
    fn count(&mut self, what: &str, min_each: usize) -> Result<usize> {
        let n = self.u64(what)?;
        let left = (self.b.len() - self.pos) as u64;
        if n.saturating_mul(min_each.max(1) as u64) > left {
            return Err(self.err(format!("{what} = {n} cannot fit in the {left} bytes left")));
        }
        Ok(n as usize)
    }
    fn text(&mut self, what: &str) -> Result<String> {
        let len = self.u32(what)? as usize;
        let bytes = self.take(len, what)?;
        std::str::from_utf8(bytes).map(str::to_string).map_err(|_| self.err(format!("{what} is not UTF-8")))
    }
    fn tensor(&mut self) -> Result<(String, Tensor)> {
        let len = self.u32("name length")? as usize;
        let name = std::str::from_utf8(self.take(len, "name")?)
            .map_err(|_| self.err("tensor name is not UTF-8"))?
            .to_string();
        let rank = self.u8("rank")? as usize;
        if rank > crate::tensor::shape::MAX_RANK {
            return Err(self.err(format!("tensor '{name}' has rank {rank}")));
        }
        let mut dims = Vec::with_capacity(rank);
        let mut numel: u64 = 1;
        for _ in 0..rank {
            let d = self.u64("dimension")?;
            numel =
                numel.checked_mul(d).ok_or_else(|| self.err(format!("tensor '{name}' size overflows")))?;
            dims.push(d);
        }
        let left = (self.b.len() - self.pos) as u64;
        if numel.saturating_mul(4) > left {
            return Err(self.err(format!(
                "tensor '{name}' {dims:?} needs {} bytes, {left} left",
                numel.saturating_mul(4)
            )));
        }
        let dims: Vec<usize> = dims
            .iter()
            .map(|&d| {
                usize::try_from(d).map_err(|_| self.err(format!("tensor '{name}' dimension {d} too large")))
            })
            .collect::<Result<_>>()?;
        let bytes = self.take(numel as usize * 4, "tensor data")?;
        let mut data = vec![0.0f32; numel as usize];
        // Copy into an aligned buffer (the file offset may be unaligned), then fix endianness.
        bytemuck::cast_slice_mut::<f32, u8>(&mut data).copy_from_slice(bytes);
        for v in data.iter_mut() {
            *v = f32::from_bits(u32::from_le(v.to_bits()));
        }
        let t = Tensor::new(&dims, data).map_err(|e| self.err(format!("tensor '{name}': {e}")))?;
        Ok((name, t))
    }
}

impl Checkpoint {
    /// Every tensor of `store` (parameters and buffers) with `config` and optional state.
    pub fn from_store(store: &ParamStore, config: &[u8], train: Option<TrainState>) -> Checkpoint {
        let tensors = store.ids().map(|id| (store.name(id).to_string(), store.get(id).clone())).collect();
        Checkpoint { config: config.to_vec(), tensors, train }
    }

    /// The file image.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
        out.extend_from_slice(&0u64.to_le_bytes()); // total length, patched below
        out.extend_from_slice(&(self.config.len() as u64).to_le_bytes());
        out.extend_from_slice(&self.config);
        out.extend_from_slice(&(self.tensors.len() as u64).to_le_bytes());
        for (n, t) in &self.tensors {
            put_tensor(&mut out, n, t);
        }
        match &self.train {
            None => out.push(0),
            Some(s) => {
                out.push(if s.run.is_empty() { 1 } else { 2 });
                out.extend_from_slice(&s.epoch.to_le_bytes());
                out.extend_from_slice(&s.step.to_le_bytes());
                for w in s.rng {
                    out.extend_from_slice(&w.to_le_bytes());
                }
                out.extend_from_slice(&(s.momentum.len() as u64).to_le_bytes());
                for (n, t) in &s.momentum {
                    put_tensor(&mut out, n, t);
                }
                if !s.run.is_empty() {
                    out.extend_from_slice(&(s.run.len() as u64).to_le_bytes());
                    for (k, v) in &s.run {
                        put_text(&mut out, k);
                        put_text(&mut out, v);
                    }
                }
            }
        }
        let total = (out.len() + 8) as u64;
        out[16..24].copy_from_slice(&total.to_le_bytes());
        let h = fnv1a64(&out);
        out.extend_from_slice(&h.to_le_bytes());
        out
    }

    /// Parses a file image; `path` only names the source in errors.
    ///
    /// # Errors
    /// `Error::Checkpoint` for a truncated, corrupted, foreign or newer-version file.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Checkpoint> {
        let err = |msg: String| Error::Checkpoint { path: path.to_path_buf(), msg };
        if bytes.len() < HEADER_LEN + 8 {
            return Err(err(format!("{} bytes is shorter than the header", bytes.len())));
        }
        if bytes[..8] != MAGIC {
            return Err(err("not a point2quad checkpoint (bad magic)".into()));
        }
        let mut r = Reader { b: bytes, pos: 8, path };
        let version = r.u32("version")?;
        if version != VERSION {
            return Err(err(format!("format version {version}, this build reads {VERSION}")));
        }
        let _reserved = r.u32("reserved")?;
        let total = r.u64("length")?;
        if total != bytes.len() as u64 {
            return Err(err(format!(
                "file is {} bytes but its header says {total} (truncated or padded)",
                bytes.len()
            )));
        }
        let body = &bytes[..bytes.len() - 8];
        let stored = u64::from_le(bytemuck::pod_read_unaligned(&bytes[bytes.len() - 8..]));
        if fnv1a64(body) != stored {
            return Err(err("checksum mismatch (file corrupted)".into()));
        }
        let mut r = Reader { b: body, pos: HEADER_LEN, path };
        let clen = r.count("config length", 1)?;
        let config = r.take(clen, "config")?.to_vec();
        let n = r.count("tensor count", 13)?;
        let mut tensors = Vec::with_capacity(n);
        for _ in 0..n {
            tensors.push(r.tensor()?);
        }
        let train = match r.u8("training-state flag")? {
            0 => None,
            flag @ (1 | 2) => {
                let epoch = r.u64("epoch")?;
                let step = r.u64("step")?;
                let mut rng = [0u64; 4];
                for w in rng.iter_mut() {
                    *w = r.u64("rng state")?;
                }
                let n = r.count("momentum count", 13)?;
                let mut momentum = Vec::with_capacity(n);
                for _ in 0..n {
                    momentum.push(r.tensor()?);
                }
                let mut run = Vec::new();
                if flag == 2 {
                    // Each pair takes at least its two 4-byte lengths.
                    let n = r.count("run record count", 8)?;
                    for _ in 0..n {
                        let k = r.text("run record key")?;
                        let v = r.text("run record value")?;
                        run.push((k, v));
                    }
                }
                Some(TrainState { epoch, step, rng, momentum, run })
            }
            f => return Err(r.err(format!("training-state flag {f}"))),
        };
        if r.pos != body.len() {
            return Err(r.err(format!("{} unexpected trailing bytes", body.len() - r.pos)));
        }
        Ok(Checkpoint { config, tensors, train })
    }

    /// Copies the tensors into `store`, which must hold exactly the same names and
    /// shapes (any order). Nothing is changed when the check fails.
    ///
    /// # Errors
    /// `Error::Checkpoint` (with `path` for context) naming the first missing,
    /// unexpected or mis-shaped tensor.
    pub fn apply_to(&self, store: &mut ParamStore, path: &Path) -> Result<()> {
        let err = |msg: String| Error::Checkpoint { path: path.to_path_buf(), msg };
        let mut ids = Vec::with_capacity(self.tensors.len());
        let mut seen = vec![false; store.len()];
        for (name, t) in &self.tensors {
            let id = store.find(name).ok_or_else(|| err(format!("tensor '{name}' is not in the model")))?;
            if seen[id.0] {
                return Err(err(format!("tensor '{name}' appears twice")));
            }
            seen[id.0] = true;
            if store.get(id).shape() != t.shape() {
                return Err(err(format!(
                    "tensor '{name}' is {} in the file, {} in the model",
                    t.shape(),
                    store.get(id).shape()
                )));
            }
            ids.push(id);
        }
        if let Some(i) = seen.iter().position(|s| !s) {
            return Err(err(format!(
                "model tensor '{}' is missing from the file",
                store.name(crate::tensor::ParamId(i))
            )));
        }
        for (id, (_, t)) in ids.into_iter().zip(&self.tensors) {
            store.get_mut(id).data_mut().copy_from_slice(t.data());
        }
        Ok(())
    }
}

/// Writes `ckpt` to `path` atomically (`crate::io::atomic::write_atomic`: temporary
/// file in the same folder, synced, then renamed), so a crash never leaves a
/// half-written checkpoint.
///
/// # Errors
/// `Error::Io` naming the path.
pub fn save(path: &Path, ckpt: &Checkpoint) -> Result<()> {
    let bytes = ckpt.to_bytes();
    crate::io::atomic::write_atomic(path, |w| w.write_all(&bytes).map_err(|e| Error::io(path, e)))
}

/// Reads and checks a checkpoint file.
///
/// # Errors
/// `Error::Io` when unreadable, `Error::Checkpoint` when invalid.
pub fn load(path: &Path) -> Result<Checkpoint> {
    let bytes = crate::io::read_input_file(path)?;
    Checkpoint::from_bytes(&bytes, path)
}
