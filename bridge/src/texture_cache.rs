//! The decoded-texture cache on disk, and the checks every texture file passes before
//! OpenImageIO reads it.
//!
//! An sRGB file's linear copy is found by what the file holds, not by its name or time: its
//! name carries a hash of the source's bytes, and a hash of the copy's own bytes, checked on
//! every use, so a replaced source gets a new copy and an edited or truncated copy is made
//! again. The directory is the user's own (0700, owned by them); when the configured one is
//! unusable the fallback is a per-user directory under the system temporary directory, checked
//! the same way, never a shared one another user could plant copies in. Copies are written
//! under a hidden name opened with `O_CREAT|O_EXCL|O_NOFOLLOW` and renamed into place, and the
//! directory is kept under a size limit by removing the least recently used copies.

use std::fs::{File, OpenOptions};
use std::io::Read;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, SystemTime};

/// How long reading a texture file may take before it is refused (plus [`READ_RATE`]'s time for
/// its size): a file on a hung network mount would otherwise stop the render for good
/// (OpenImageIO's reads block with it).
pub const OPEN_TIMEOUT: Duration = Duration::from_secs(20);

/// The slowest read rate allowed on top of [`OPEN_TIMEOUT`], bytes per second (8 MB/s): a large
/// texture on a slow but working disk is not refused.
pub const READ_RATE: u64 = 8_000_000;

/// The cache's size limit when `$MIPRAY_TEXTURE_CACHE_MB` does not set one, MB (10^6 bytes).
pub const DEFAULT_LIMIT_MB: u64 = 4096;

/// Suffix of every copy the cache holds (eviction touches nothing else).
const SUFFIX: &str = ".linear.exr";

/// Why a texture file is not opened: `path` is refused before OpenImageIO sees it unless it is
/// a regular file whose every byte arrives within `timeout` plus its size at [`READ_RATE`]. A
/// device (`/dev/zero`), a FIFO or a socket would have OpenImageIO's format probes read for
/// ever. Once read whole, the file is in the page cache: OpenImageIO's own reads, the linear
/// copy's conversion and its content hash then find it there (a mount that stalls after this
/// read and also loses the cached pages can still block them).
pub fn check_source(path: &Path, timeout: Duration) -> Result<(), String> {
    let meta = std::fs::metadata(path).map_err(|e| format!("cannot read: {e}"))?;
    if !meta.is_file() {
        return Err(format!("not a regular file ({}); a texture must be an image file", kind_of(&meta)));
    }
    probe(path, timeout + Duration::from_secs(meta.len() / READ_RATE))
}

/// What a non-regular file is, for the message.
fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_dir() {
        "a directory"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a plain file"
    }
}

/// Reads `path` to its end on a thread of its own and waits at most `timeout` for it. A read
/// that never returns leaves that thread blocked (nothing can cancel a blocked read) but not
/// the render. A file that sends its first bytes and then stalls is refused too.
pub fn probe(path: &Path, timeout: Duration) -> Result<(), String> {
    let (send, receive) = mpsc::channel();
    let owned = path.to_path_buf();
    let spawned = std::thread::Builder::new().name("mipray-texture-probe".into()).spawn(move || {
        let read = File::open(&owned).and_then(|f| std::io::copy(&mut std::io::BufReader::with_capacity(1 << 20, f), &mut std::io::sink()));
        let _ = send.send(read.map(|_| ()).map_err(|e| e.to_string()));
    });
    if spawned.is_err() {
        // No thread to spare: read here rather than refuse a file that is probably fine.
        return File::open(path).and_then(|mut f| f.read(&mut [0u8; 16])).map(|_| ()).map_err(|e| format!("cannot read: {e}"));
    }
    match receive.recv_timeout(timeout) {
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => Err(format!("cannot read: {e}")),
        Err(_) => Err(format!("reading it took longer than {} s; refused", timeout.as_secs_f32())),
    }
}

/// A 128-bit hash of `bytes` (two 64-bit lanes over 8-byte words, FNV-style, with the length):
/// stable across builds and Rust versions, as a file name must be. It tells file versions
/// apart; it is no defence against a chosen collision, which the private directory is.
pub fn hash128(bytes: &[u8]) -> u128 {
    const P1: u64 = 0x0000_0100_0000_01b3;
    const P2: u64 = 0x9e37_79b9_7f4a_7c15;
    let (mut a, mut b) = (0xcbf2_9ce4_8422_2325u64, 0x8422_2325_cbf2_9ce4u64);
    let mut chunks = bytes.chunks_exact(8);
    for c in &mut chunks {
        let w = u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
        a = (a ^ w).wrapping_mul(P1);
        b = (b ^ w.rotate_left(29)).wrapping_mul(P2) ^ (b >> 31);
    }
    for &x in chunks.remainder() {
        a = (a ^ u64::from(x)).wrapping_mul(P1);
        b = (b ^ u64::from(x)).wrapping_mul(P2) ^ (b >> 31);
    }
    a = (a ^ bytes.len() as u64).wrapping_mul(P1);
    b = (b ^ a).wrapping_mul(P2);
    (u128::from(a) << 64) | u128::from(b)
}

/// The hash of a file's bytes.
pub fn hash_file(path: &Path) -> std::io::Result<u128> {
    Ok(hash128(&std::fs::read(path)?))
}

/// The user's effective id.
fn euid() -> u32 {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

/// `dir` made ready as a private cache directory: created 0700 if missing, and then it must be
/// a directory owned by this user that no one else can write (a group- or world-writable one of
/// ours is made 0700). `strict` (the shared temporary directory's fallback) also refuses a
/// symbolic link and any mode but 0700.
pub fn private_dir(dir: &Path, strict: bool) -> Result<(), String> {
    std::fs::DirBuilder::new().recursive(true).mode(0o700).create(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let meta = if strict { std::fs::symlink_metadata(dir) } else { std::fs::metadata(dir) }
        .map_err(|e| format!("cannot read {}: {e}", dir.display()))?;
    if !meta.is_dir() {
        return Err(format!("{} is not a directory", dir.display()));
    }
    if meta.uid() != euid() {
        return Err(format!("{} belongs to another user (uid {})", dir.display(), meta.uid()));
    }
    let open_to_others = if strict { meta.mode() & 0o077 != 0 } else { meta.mode() & 0o022 != 0 };
    if open_to_others {
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700))
            .map_err(|e| format!("{} is writable by others and cannot be made private: {e}", dir.display()))?;
    }
    Ok(())
}

/// The per-user fallback under the system temporary directory.
pub fn fallback_dir() -> PathBuf {
    std::env::temp_dir().join(format!("mipray-textures-{}", euid()))
}

/// The size limit in bytes: `$MIPRAY_TEXTURE_CACHE_MB` (MB, 10^6 bytes) or [`DEFAULT_LIMIT_MB`].
pub fn limit_bytes() -> u64 {
    let mb =
        std::env::var("MIPRAY_TEXTURE_CACHE_MB").ok().and_then(|v| v.trim().parse::<f64>().ok()).filter(|v| v.is_finite() && *v >= 0.0);
    mb.map_or(DEFAULT_LIMIT_MB * 1_000_000, |mb| (mb * 1e6) as u64)
}

/// The name prefix of `source`'s copies: its stem and the hash of its bytes (and of how it is
/// decoded, `recipe`). The copy's own hash follows it.
pub fn entry_prefix(source: &Path, source_hash: u128, recipe: &str) -> String {
    let stem: String = source
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("texture")
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '_' })
        .take(64)
        .collect();
    let key = hash128(format!("{recipe}\0{source_hash:032x}").as_bytes());
    format!("{stem}-{key:032x}-")
}

/// A whole copy in `dir` whose name starts with `prefix`: its own bytes must hash to the hash
/// its name ends with. A copy that does not (edited, truncated) is removed, so it is made again.
/// A copy found is marked used now (its access time), for [`evict`].
pub fn find(dir: &Path, prefix: &str) -> Option<PathBuf> {
    let entries = std::fs::read_dir(dir).ok()?;
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        let Some(stated) = name.strip_prefix(prefix).and_then(|rest| rest.strip_suffix(SUFFIX)) else { continue };
        let path = entry.path();
        let whole = std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_file())
            && u128::from_str_radix(stated, 16).ok().is_some_and(|h| hash_file(&path).is_ok_and(|actual| actual == h));
        if whole {
            if let Ok(f) = File::open(&path) {
                let _ = f.set_times(std::fs::FileTimes::new().set_accessed(SystemTime::now()));
            }
            return Some(path);
        }
        log::warn!("texture cache: {} does not hold what its name says (edited or cut short); making it again", path.display());
        let _ = std::fs::remove_file(&path);
    }
    None
}

/// A hidden file in `dir` for a copy being written, created here (`O_CREAT|O_EXCL|O_NOFOLLOW`,
/// 0600) so nothing planted under its name is written through.
pub fn new_partial(dir: &Path, prefix: &str) -> Result<PathBuf, String> {
    use std::sync::atomic::{AtomicU64, Ordering};
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    let path = dir.join(format!(".{prefix}{}-{n}.partial.exr", std::process::id()));
    OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&path)
        .map_err(|e| format!("cannot create {}: {e}", path.display()))?;
    Ok(path)
}

/// Moves the finished `partial` into place as `prefix` + its hash + the suffix.
pub fn commit(dir: &Path, prefix: &str, partial: &Path) -> Result<PathBuf, String> {
    let hash = hash_file(partial).map_err(|e| format!("cannot read {}: {e}", partial.display()))?;
    let copy = dir.join(format!("{prefix}{hash:032x}{SUFFIX}"));
    std::fs::rename(partial, &copy).map_err(|e| format!("cannot write {}: {e}", copy.display()))?;
    Ok(copy)
}

/// Removes the least recently used copies in `dir` until they hold at most `limit` bytes,
/// keeping `keep` (the copy just made) whatever its size. Returns the bytes removed.
pub fn evict(dir: &Path, limit: u64, keep: &Path) -> u64 {
    let Ok(entries) = std::fs::read_dir(dir) else { return 0 };
    let mut copies: Vec<(SystemTime, u64, PathBuf)> = entries
        .flatten()
        .filter(|e| e.file_name().to_str().is_some_and(|n| n.ends_with(SUFFIX) && !n.starts_with('.')))
        .filter_map(|e| {
            let meta = std::fs::symlink_metadata(e.path()).ok()?;
            let used = meta.accessed().or_else(|_| meta.modified()).ok()?;
            meta.is_file().then(|| (used, meta.len(), e.path()))
        })
        .collect();
    let mut total: u64 = copies.iter().map(|c| c.1).sum();
    copies.sort();
    let mut removed = 0;
    for (_, size, path) in copies {
        if total <= limit {
            break;
        }
        if path == keep {
            continue;
        }
        if std::fs::remove_file(&path).is_ok() {
            log::info!("texture cache: removed {} (least recently used; the cache holds at most {limit} bytes)", path.display());
            total -= size;
            removed += size;
        }
    }
    removed
}

/// Runs `f` with the process's standard error caught, and returns what was written there with
/// `f`'s result. libpng and other image libraries print their own lines (`libpng error: IHDR:
/// ...`) beside the error OpenImageIO returns; caught, they reach the log as part of one line
/// naming the file. Another thread's output in that window is caught too and handed back.
pub fn catching_stderr<T>(f: impl FnOnce() -> T) -> (T, String) {
    use std::io::{Seek, SeekFrom};
    use std::os::fd::AsRawFd;
    let Ok(mut sink) = tempfile_in_tmp() else { return (f(), String::new()) };
    // SAFETY: dup and dup2 on valid descriptors; 2 is restored before returning.
    let saved = unsafe { libc::dup(2) };
    if saved < 0 || unsafe { libc::dup2(sink.as_raw_fd(), 2) } < 0 {
        if saved >= 0 {
            // SAFETY: `saved` is ours.
            unsafe { libc::close(saved) };
        }
        return (f(), String::new());
    }
    let out = f();
    // SAFETY: as above.
    unsafe {
        libc::dup2(saved, 2);
        libc::close(saved);
    }
    let mut text = String::new();
    let _ = sink.seek(SeekFrom::Start(0)).and_then(|_| sink.read_to_string(&mut text));
    (out, text)
}

/// An unnamed temporary file (`O_TMPFILE`): nothing to clean up, nothing another user can open.
fn tempfile_in_tmp() -> std::io::Result<File> {
    OpenOptions::new().read(true).write(true).mode(0o600).custom_flags(libc::O_TMPFILE).open(std::env::temp_dir())
}

/// The lines of `caught` worth passing on: other mipray lines as they were (another thread's),
/// the libraries' own as one line.
pub fn pass_on(path: &str, caught: &str) {
    let mut foreign = Vec::new();
    for line in caught.lines().map(str::trim).filter(|l| !l.is_empty()) {
        if line.starts_with("mipray") {
            eprintln!("{line}");
        } else {
            foreign.push(line);
        }
    }
    if !foreign.is_empty() {
        log::info!("texture {path}: the image library said: {}", foreign.join("; "));
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn scratch(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("mipray-txcache-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn what_a_library_prints_is_caught_not_left_on_the_terminal() {
        let (value, caught) = catching_stderr(|| {
            // SAFETY: a plain write of a static buffer to descriptor 2.
            unsafe { libc::write(2, b"libpng error: IHDR\n".as_ptr().cast(), 19) };
            7
        });
        assert_eq!((value, caught.as_str()), (7, "libpng error: IHDR\n"));
        let (_, after) = catching_stderr(|| ());
        assert_eq!(after, "", "descriptor 2 is restored and the next catch starts empty");
    }

    #[test]
    fn devices_fifos_and_directories_are_refused_by_kind() {
        let dir = scratch("kinds");
        let fifo = dir.join("pipe.png");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        for (path, kind) in [(Path::new("/dev/zero"), "a device"), (fifo.as_path(), "a FIFO"), (dir.as_path(), "a directory")] {
            let err = check_source(path, OPEN_TIMEOUT).unwrap_err();
            assert!(err.contains(kind), "{}: {err}", path.display());
        }
    }

    #[test]
    fn a_file_whose_first_bytes_never_come_is_refused_in_time() {
        // A FIFO with no writer blocks its reader, as a file on a hung mount does.
        let dir = scratch("probe");
        let fifo = dir.join("hung");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let started = std::time::Instant::now();
        let err = probe(&fifo, Duration::from_millis(300)).unwrap_err();
        assert!(err.contains("longer than"), "{err}");
        assert!(started.elapsed() < Duration::from_secs(5));
        // Let the blocked probe thread finish.
        let _ = OpenOptions::new().write(true).custom_flags(libc::O_NONBLOCK).open(&fifo);
        let ok = scratch("probe-ok").join("f.png");
        std::fs::write(&ok, b"\x89PNG").unwrap();
        probe(&ok, Duration::from_secs(5)).unwrap();
    }

    #[test]
    fn a_file_that_sends_a_header_then_stalls_is_refused_in_time() {
        // Only its first bytes were waited for: a file whose reading stalled after a valid
        // header passed, and OpenImageIO's read then blocked for good. A FIFO whose writer sends
        // a PNG signature and keeps the pipe open stands for a mount that stalls mid-file.
        let dir = scratch("stall");
        let fifo = dir.join("stalls.png");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let (done_send, done_receive) = mpsc::channel::<()>();
        let writer_path = fifo.clone();
        let writer = std::thread::spawn(move || {
            use std::io::Write;
            let mut w = OpenOptions::new().write(true).open(&writer_path).unwrap();
            w.write_all(b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR").unwrap();
            w.flush().unwrap();
            // Hold the pipe open (no end of file) until the probe has given up.
            let _ = done_receive.recv_timeout(Duration::from_secs(30));
        });
        let err = probe(&fifo, Duration::from_millis(500)).unwrap_err();
        assert!(err.contains("longer than"), "{err}");
        done_send.send(()).unwrap();
        writer.join().unwrap();
    }

    #[test]
    fn hashes_tell_one_changed_byte_and_length_apart() {
        let a = vec![7u8; 1000];
        let mut b = a.clone();
        b[999] = 8;
        assert_ne!(hash128(&a), hash128(&b));
        assert_ne!(hash128(&a), hash128(&a[..999]));
        assert_ne!(hash128(&[]), hash128(&[0]));
        assert_eq!(hash128(&a), hash128(&a.clone()));
    }

    #[test]
    fn a_directory_of_another_mode_is_made_private_and_a_link_refused_when_strict() {
        let dir = scratch("private");
        let open = dir.join("open");
        std::fs::create_dir(&open).unwrap();
        std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o777)).unwrap();
        private_dir(&open, true).unwrap();
        assert_eq!(std::fs::metadata(&open).unwrap().mode() & 0o777, 0o700);
        let link = dir.join("link");
        std::os::unix::fs::symlink(&open, &link).unwrap();
        assert!(private_dir(&link, true).is_err(), "a planted link in /tmp is not followed");
        private_dir(&link, false).unwrap();
        let fresh = dir.join("a/b");
        private_dir(&fresh, true).unwrap();
        assert_eq!(std::fs::metadata(&fresh).unwrap().mode() & 0o777, 0o700);
    }

    #[test]
    fn a_partial_file_is_never_written_through_a_planted_name() {
        let dir = scratch("excl");
        let first = new_partial(&dir, "x-").unwrap();
        assert!(first.file_name().unwrap().to_str().unwrap().starts_with('.'));
        // A link planted where the next name would go: creating through it fails.
        let target = dir.join("victim");
        std::fs::write(&target, b"keep").unwrap();
        let planted = dir.join(format!(".x-{}-1.partial.exr", std::process::id()));
        std::os::unix::fs::symlink(&target, &planted).unwrap();
        assert!(new_partial(&dir, "x-").is_err());
        assert_eq!(std::fs::read(&target).unwrap(), b"keep");
    }

    #[test]
    fn copies_are_found_only_whole_and_evicted_least_recently_used_first() {
        let dir = scratch("lru");
        let mut made = Vec::new();
        for (i, prefix) in ["a-", "b-", "c-"].iter().enumerate() {
            let partial = new_partial(&dir, prefix).unwrap();
            std::fs::write(&partial, vec![i as u8; 1000]).unwrap();
            let copy = commit(&dir, prefix, &partial).unwrap();
            let when = SystemTime::UNIX_EPOCH + Duration::from_secs(1_000_000 + i as u64 * 1000);
            File::open(&copy).unwrap().set_times(std::fs::FileTimes::new().set_accessed(when)).unwrap();
            made.push(copy);
        }
        assert_eq!(find(&dir, "b-"), Some(made[1].clone()), "b is used now: the most recent");
        // a is the least recently used: it goes first; b (just used) and c stay.
        assert_eq!(evict(&dir, 2000, &made[2]), 1000);
        assert!(!made[0].exists() && made[1].exists() && made[2].exists());
        // c truncated: not found, and removed so that it is made again.
        std::fs::write(&made[2], vec![2u8; 10]).unwrap();
        assert_eq!(find(&dir, "c-"), None);
        assert!(!made[2].exists());
        assert_eq!(evict(&dir, 0, &made[1]), 0, "the copy in use is kept whatever the limit");
    }
}
