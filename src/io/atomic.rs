//! Atomic file writes: the content goes to a uniquely named temporary file in the
//! target's directory, is flushed to disk, and only then renamed over the target.
//! A reader never sees a half-written file, and a failed write leaves nothing behind.

use crate::error::{Error, Result};
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Distinguishes temporary files made by threads of the same process.
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes a file atomically: `f` writes the content into a buffered writer on a
/// temporary file in the same directory as `path` (so the rename cannot cross file
/// systems); the file is flushed and synced, then renamed over `path`.
///
/// # Errors
/// `Io` naming `path` when the temporary file cannot be created, written, synced or
/// renamed (an I/O error raised while `f` writes is reported this way too, in place
/// of whatever `f` made of it); any other error `f` returns is passed on. On every
/// error the temporary file is removed and `path` is left as it was.
pub fn write_atomic(path: &Path, f: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    prepare_atomic(path, f)?.commit()
}

/// A fully written, synced temporary file waiting to be renamed over its target by
/// [`Staged::commit`]. Dropped without a commit (an error in a later step), it removes
/// the temporary file and the target stays as it was.
#[derive(Debug)]
pub struct Staged {
    tmp: Option<PathBuf>,
    path: PathBuf,
}

impl Staged {
    /// The target path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Renames the temporary file over the target.
    ///
    /// # Errors
    /// `Io` naming the target when the rename fails (the temporary file is removed).
    pub fn commit(mut self) -> Result<()> {
        let Some(tmp) = self.tmp.take() else { return Ok(()) };
        fs::rename(&tmp, &self.path).map_err(|e| {
            let _ = fs::remove_file(&tmp);
            Error::io(&self.path, e)
        })
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        if let Some(tmp) = self.tmp.take() {
            // Best effort, as in `write_atomic`.
            let _ = fs::remove_file(tmp);
        }
    }
}

/// The first half of [`write_atomic`]: writes and syncs the temporary file but does not
/// rename it. A command with several outputs stages them all and commits only when
/// every one was written, so a failure on the last leaves every earlier target as it
/// was (a failed `--svg` preview must not cost the mesh written before it, or, with
/// `-o` naming an existing file, that file's old content).
///
/// # Errors
/// As [`write_atomic`]; on error nothing is left behind.
pub fn prepare_atomic(path: &Path, f: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<Staged> {
    let (tmp, file) = create_temp(path)?;
    match write_and_sync(path, file, f) {
        Ok(()) => Ok(Staged { tmp: Some(tmp), path: path.to_path_buf() }),
        Err(e) => {
            // Best effort: the original error matters more than a failed clean-up.
            let _ = fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// Commits staged writes in order (see [`prepare_atomic`]).
///
/// # Errors
/// The first failed rename's error; the files after it are not committed (their
/// temporary files are removed).
pub fn commit_all(staged: Vec<Staged>) -> Result<()> {
    staged.into_iter().try_for_each(Staged::commit)
}

/// Whether `path`'s text names a folder whatever exists: it ends with a separator (`/`,
/// and `\\` on Windows), or its last component is `.` or `..`. [`Path::file_name`] reads
/// `p.svg/` and `p.svg/.` as `p.svg`, so a write would make the temporary file and fail
/// only at the rename (session 41's audit).
pub fn names_a_folder(path: &Path) -> bool {
    let text = path.as_os_str().to_string_lossy();
    let seps: &[char] = &['/', std::path::MAIN_SEPARATOR];
    if text.ends_with(seps) {
        return true;
    }
    let last = text.rsplit(seps).next().unwrap_or("");
    last == "." || last == ".."
}

/// Creates a new temporary file next to `path`. `create_new` makes the name
/// exclusive even against other processes; on a clash the next name is tried.
fn create_temp(path: &Path) -> Result<(PathBuf, File)> {
    // `dir/name/` and `dir/name/.` have the components of `dir/name`, but the rename onto
    // them fails (not a folder): refused before anything is written.
    if names_a_folder(path) {
        let msg = "not a file path (it ends with a path separator, `.` or `..`)";
        return Err(Error::io(path, io::Error::new(io::ErrorKind::InvalidInput, msg)));
    }
    let file_name = path
        .file_name()
        .ok_or_else(|| Error::io(path, io::Error::new(io::ErrorKind::InvalidInput, "not a file path")))?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let pid = process_id();
    let mut last_err = None;
    for _ in 0..100 {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let mut name = std::ffi::OsString::from(".");
        name.push(temp_stem(file_name));
        name.push(format!(".{pid}.{n}.tmp"));
        let tmp = dir.join(name);
        match OpenOptions::new().write(true).create_new(true).open(&tmp) {
            Ok(file) => return Ok((tmp, file)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => last_err = Some(e),
            Err(e) => return Err(Error::io(path, e)),
        }
    }
    let e = last_err.unwrap_or_else(|| io::Error::other("could not create a temporary file"));
    Err(Error::io(path, e))
}

/// The part of an output's file name its temporary file's name starts with: the whole
/// name up to 200 bytes, else its first 200 bytes' worth of characters, so that the
/// temporary name (with its dot, process id and counter) stays within the 255 bytes file
/// systems allow where the output's own name fits (session 24's audit: names of 235 to
/// 255 bytes failed at the end of the work). Only a temporary name: it need not be the
/// exact bytes, just a valid name in the same folder.
fn temp_stem(file_name: &std::ffi::OsStr) -> std::ffi::OsString {
    const MAX: usize = 200;
    if file_name.len() <= MAX {
        return file_name.to_os_string();
    }
    let lossy = file_name.to_string_lossy();
    let mut end = MAX;
    while !lossy.is_char_boundary(end) {
        end -= 1;
    }
    lossy[..end].into()
}

/// The process id where the platform has one (wasm32-unknown-unknown panics on
/// `std::process::id`); only used to make temporary names readable and rarely clash.
fn process_id() -> u32 {
    #[cfg(not(all(target_family = "wasm", target_os = "unknown")))]
    {
        std::process::id()
    }
    #[cfg(all(target_family = "wasm", target_os = "unknown"))]
    {
        0
    }
}

fn write_and_sync(path: &Path, file: File, f: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let w = run_tracked(path, BufWriter::new(file), f)?;
    let file = w.into_inner().map_err(|e| Error::io(path, e.into_error()))?;
    file.sync_all().map_err(|e| Error::io(path, e))
}

/// Runs the content writer on `w`; an I/O error it met is reported naming `path`.
fn run_tracked<W: Write>(path: &Path, w: W, f: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<W> {
    let mut t = Tracking { inner: w, first_err: None };
    let r = f(&mut t);
    if let Some(e) = t.first_err.take() {
        return Err(Error::io(path, e));
    }
    r?;
    t.flush().map_err(|e| Error::io(path, e))?;
    Ok(t.inner)
}

/// A writer that remembers the first I/O error, so that it can be reported with
/// the path even when the content writer had no path to name.
struct Tracking<W: Write> {
    inner: W,
    first_err: Option<io::Error>,
}

impl<W: Write> Tracking<W> {
    fn note<T>(&mut self, r: io::Result<T>) -> io::Result<T> {
        if let Err(e) = &r {
            if self.first_err.is_none() {
                self.first_err = Some(io::Error::new(e.kind(), e.to_string()));
            }
        }
        r
    }
}

impl<W: Write> Write for Tracking<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let r = self.inner.write(buf);
        self.note(r)
    }
    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        let r = self.inner.write_all(buf);
        self.note(r)
    }
    fn flush(&mut self) -> io::Result<()> {
        let r = self.inner.flush();
        self.note(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Staged writes replace nothing until committed: dropped, they leave the targets
    /// as they were and no temporary file; committed, every target has its content.
    #[test]
    fn staged_writes_replace_targets_only_when_committed() {
        let d = scratch_dir("staged");
        let (a, b) = (d.join("a.txt"), d.join("b.txt"));
        fs::write(&a, b"old a").unwrap();
        let sa = prepare_atomic(&a, |w| w.write_all(b"new a").map_err(|e| Error::io("a", e))).unwrap();
        let sb = prepare_atomic(&b, |w| w.write_all(b"new b").map_err(|e| Error::io("b", e))).unwrap();
        assert_eq!(fs::read(&a).unwrap(), b"old a");
        assert!(!b.exists());
        drop((sa, sb));
        assert_eq!(fs::read(&a).unwrap(), b"old a");
        assert_eq!(fs::read_dir(&d).unwrap().count(), 1, "temporary files left behind");
        let sa = prepare_atomic(&a, |w| w.write_all(b"new a").map_err(|e| Error::io("a", e))).unwrap();
        let sb = prepare_atomic(&b, |w| w.write_all(b"new b").map_err(|e| Error::io("b", e))).unwrap();
        assert_eq!(sb.path(), b.as_path());
        commit_all(vec![sa, sb]).unwrap();
        assert_eq!((fs::read(&a).unwrap(), fs::read(&b).unwrap()), (b"new a".to_vec(), b"new b".to_vec()));
        assert_eq!(fs::read_dir(&d).unwrap().count(), 2);
        let _ = fs::remove_dir_all(&d);
    }

    fn scratch_dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!(
            "p2q_atomic_{tag}_{}_{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = fs::remove_dir_all(&d);
        fs::create_dir_all(&d).unwrap();
        d
    }

    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    /// A target ending with a separator names a folder: refused before anything is
    /// written (it used to be written as a temporary file and fail only at the rename,
    /// after the outputs staged before it were committed).
    #[test]
    fn a_target_ending_with_a_separator_is_refused_before_writing() {
        let d = scratch_dir("slash");
        for tail in ["p.svg/", "p.svg/.", "p.svg/.."] {
            let target = format!("{}/{tail}", d.display());
            let err =
                prepare_atomic(Path::new(&target), |w| w.write_all(b"x").map_err(|e| Error::io("x", e)))
                    .unwrap_err()
                    .to_string();
            assert!(err.contains(tail) && err.contains("separator"), "{err}");
            assert!(entries(&d).is_empty(), "{:?}", entries(&d));
        }
        assert!(!names_a_folder(Path::new("a/b.obj")) && !names_a_folder(Path::new("a/.b")));
        assert!(names_a_folder(Path::new(".")) && names_a_folder(Path::new("..")));
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn writes_and_replaces() {
        let d = scratch_dir("ok");
        let p = d.join("a.txt");
        write_atomic(&p, |w| w.write_all(b"one").map_err(|e| Error::io("x", e))).unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"one");
        write_atomic(&p, |w| w.write_all(b"two!").map_err(|e| Error::io("x", e))).unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"two!");
        assert_eq!(entries(&d), vec!["a.txt"]);
        fs::remove_dir_all(&d).unwrap();
    }

    /// A name of 255 bytes (the usual limit), ASCII or with multibyte characters at the
    /// cut, is written and leaves no temporary file (the temporary name was 255 + 12
    /// bytes and the write failed).
    #[test]
    fn the_longest_names_are_written() {
        let d = scratch_dir("long");
        // The second cuts inside a two-byte character (byte 200 is an `é`'s second byte).
        for name in
            ["a".repeat(251) + ".obj", "a".to_string() + &"é".repeat(124) + "x.obj", "a".repeat(200) + ".off"]
        {
            assert!(name.len() <= 255 && name.len() >= 200, "{}", name.len());
            let p = d.join(&name);
            write_atomic(&p, |w| w.write_all(b"one").map_err(|e| Error::io("x", e))).unwrap();
            assert_eq!(fs::read(&p).unwrap(), b"one");
            assert_eq!(entries(&d), vec![name.clone()]);
            fs::remove_file(&p).unwrap();
        }
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn failing_writer_leaves_no_file_and_no_temp() {
        let d = scratch_dir("fail_new");
        let p = d.join("new.obj");
        let err = write_atomic(&p, |w| {
            w.write_all(&[b'x'; 100_000]).map_err(|e| Error::io("x", e))?;
            Err(Error::invalid("stopped midway"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("stopped midway"), "{err}");
        assert!(entries(&d).is_empty(), "{:?}", entries(&d));
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn failing_writer_leaves_existing_file_untouched() {
        let d = scratch_dir("fail_old");
        let p = d.join("old.obj");
        fs::write(&p, b"precious").unwrap();
        let r = write_atomic(&p, |w| {
            w.write_all(b"garbage").map_err(|e| Error::io("x", e))?;
            Err(Error::invalid("no"))
        });
        assert!(r.is_err());
        assert_eq!(fs::read(&p).unwrap(), b"precious");
        assert_eq!(entries(&d), vec!["old.obj"]);
        fs::remove_dir_all(&d).unwrap();
    }

    /// An I/O error inside the content writer is reported with the target path,
    /// even when the content writer itself had no path to name.
    #[test]
    fn io_error_names_the_path() {
        let p = Path::new("some/dir/x.off");
        let err = run_tracked(p, FailWriter, |w| w.write_all(b"abc").map_err(|e| Error::io("<output>", e)))
            .err()
            .expect("must fail");
        let msg = err.to_string();
        assert!(msg.contains("some/dir/x.off") && msg.contains("disk full"), "{msg}");

        let d = scratch_dir("ioerr");
        let missing = d.join("no_such_dir").join("f.obj");
        let err = write_atomic(&missing, |_| Ok(())).unwrap_err().to_string();
        assert!(err.contains("no_such_dir"), "{err}");
        fs::remove_dir_all(&d).unwrap();
    }

    struct FailWriter;
    impl Write for FailWriter {
        fn write(&mut self, _: &[u8]) -> io::Result<usize> {
            Err(io::Error::other("disk full"))
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }
}
