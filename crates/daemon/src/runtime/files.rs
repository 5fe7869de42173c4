//! Opening and creating the daemon's files in its log directory, so that nothing planted there
//! redirects them and no file is ever seen half made.
//!
//! - Every file is opened with `O_NOFOLLOW`, and a directory the daemon writes in
//!   (`diagnosis-NAME/`) is checked to be one: a symbolic link in the log directory, planted by
//!   whoever can write there, is refused with [`DaemonError::LogLink`], never followed to the
//!   file it names. The log directory itself may be a link: that is the operator's choice.
//! - A file that starts with a header ([`create_with_header`]) is made under a temporary name,
//!   its header written and synced, and only then linked to its own name: whenever the daemon
//!   is killed, the name is absent or names a file that holds its header.
//! - A history (the health CSV, the diagnosis JSONL: [`open_history`]) is appended to, run after
//!   run; it is created with its header when missing, a line cut by a crash is cut off, and a
//!   file that starts with another header is refused.
//!
//! Hand-written because std has the one flag needed (`O_NOFOLLOW` through `OpenOptionsExt`) and
//! a crate that confines paths to a directory (cap-std) would replace all of the daemon's file
//! handling for the same checks.
//!
//! Not here: writing rows and outliving a full disk ([`crate::runtime::log_file`]).

use std::fs::File;
use std::io::{self, Read, Seek, SeekFrom, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

use crate::error::DaemonError;

/// Most names tried for a new file or directory (`NAME`, `NAME-1`, ...).
const NAME_TRIES: usize = 1000;

/// Options that refuse a symbolic link at the path's last component.
fn no_follow() -> std::fs::OpenOptions {
    let mut o = File::options();
    o.custom_flags(libc::O_NOFOLLOW);
    o
}

/// True when `path` is a symbolic link (not followed).
fn is_link(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink())
}

/// The error of a failed open of `path`: a link refused, or why it could not be opened.
fn open_error(path: &Path, source: io::Error) -> DaemonError {
    if source.raw_os_error() == Some(libc::ELOOP) || is_link(path) {
        DaemonError::LogLink {
            path: path.to_path_buf(),
        }
    } else {
        DaemonError::LogFile {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Ignores SIGXFSZ for the whole process: past a file-size limit (systemd's `LimitFSIZE=`,
/// `ulimit -f`) a write then fails with EFBIG, which the log survives like a full disk,
/// instead of the signal killing the daemon before its stop action.
#[allow(unsafe_code)]
pub(crate) fn ignore_file_size_signal() {
    // SAFETY: SIG_IGN is a disposition, not a handler: no code of ours runs on the signal.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

/// Creates a new file in `dir` holding `header`, under the first free name of `names`: the
/// header is written and synced under the temporary name `temp` first, then the file is linked
/// to its name. Its path and the file, open for writing after the header.
pub(crate) fn create_with_header(
    dir: &Path,
    temp: &str,
    names: impl IntoIterator<Item = String>,
    header: &[u8],
) -> Result<(PathBuf, File), DaemonError> {
    let temp = dir.join(temp);
    let mut file = create_temp(&temp)?;
    let written = file.write_all(header).and_then(|()| file.sync_data());
    let linked = written
        .map_err(|source| DaemonError::LogWrite {
            path: temp.clone(),
            source,
        })
        .and_then(|()| link_to_free_name(&temp, dir, names));
    // The temporary name goes whatever happened: a file that has one is linked or no use.
    let _gone = std::fs::remove_file(&temp);
    linked.map(|path| (path, file))
}

/// Opens the temporary file `temp` new; one a crash left there is removed first, a link
/// planted there refused.
fn create_temp(temp: &Path) -> Result<File, DaemonError> {
    let open = || no_follow().write(true).create_new(true).open(temp);
    match open() {
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists && !is_link(temp) => {
            std::fs::remove_file(temp).map_err(|source| DaemonError::LogFile {
                path: temp.to_path_buf(),
                source,
            })?;
            open().map_err(|e| open_error(temp, e))
        }
        opened => opened.map_err(|e| open_error(temp, e)),
    }
}

/// Links `temp` to the first name of `names` not taken in `dir`; its path.
fn link_to_free_name(
    temp: &Path,
    dir: &Path,
    names: impl IntoIterator<Item = String>,
) -> Result<PathBuf, DaemonError> {
    let mut last = dir.to_path_buf();
    for name in names.into_iter().take(NAME_TRIES) {
        let path = dir.join(name);
        match std::fs::hard_link(temp, &path) {
            Ok(()) => return Ok(path),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => last = path,
            // A file system without hard links (FAT): the file is renamed to a name seen free.
            Err(_) if std::fs::symlink_metadata(&path).is_err() => {
                return std::fs::rename(temp, &path)
                    .map(|()| path.clone())
                    .map_err(|source| DaemonError::LogFile { path, source });
            }
            Err(source) => return Err(DaemonError::LogFile { path, source }),
        }
    }
    Err(DaemonError::LogFile {
        path: last,
        source: io::Error::new(io::ErrorKind::AlreadyExists, "every name tried is taken"),
    })
}

/// Opens the history `path` to append to, created with `header` (if any) when missing. An
/// existing file must start with `header`; a last line cut by a crash is cut off. The file and
/// its size.
pub(crate) fn open_history(path: &Path, header: &[u8]) -> Result<(File, u64), DaemonError> {
    let opened = no_follow().read(true).append(true).open(path);
    let mut file = match opened {
        Ok(file) => file,
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            let (dir, name) = split(path)?;
            let (_, file) = create_with_header(dir, &format!("{name}.part"), [name], header)?;
            return Ok((file, header.len() as u64));
        }
        Err(e) => return Err(open_error(path, e)),
    };
    let io = |source| DaemonError::LogFile {
        path: path.to_path_buf(),
        source,
    };
    let len = file.metadata().map_err(io)?.len();
    let mut start = vec![0; header.len().min(len as usize)];
    file.read_exact(&mut start).map_err(io)?;
    if !header.starts_with(&start) {
        return Err(DaemonError::LogHeader {
            path: path.to_path_buf(),
        });
    }
    if start.len() < header.len() {
        // Empty, or a header cut by a crash: the header, whole.
        file.set_len(0)
            .and_then(|()| file.write_all(header))
            .map_err(io)?;
        return Ok((file, header.len() as u64));
    }
    let whole = whole_lines(&mut file, len).map_err(io)?;
    if whole < len {
        tracing::warn!(
            file = %path.display(),
            "the last line of the history was cut ({} bytes, by a crash or a full disk); it is dropped",
            len - whole
        );
        file.set_len(whole).map_err(io)?;
    }
    Ok((file, whole))
}

/// The length of `file` (of `len` bytes) up to the end of its last whole line.
fn whole_lines(file: &mut File, len: u64) -> io::Result<u64> {
    let mut end = len;
    let mut chunk = [0u8; 4096];
    while end > 0 {
        let from = end.saturating_sub(chunk.len() as u64);
        let n = (end - from) as usize;
        file.seek(SeekFrom::Start(from))?;
        file.read_exact(&mut chunk[..n])?;
        if let Some(i) = chunk[..n].iter().rposition(|&b| b == b'\n') {
            return Ok(from + i as u64 + 1);
        }
        end = from;
    }
    Ok(0)
}

/// The directory and the file name of `path`.
fn split(path: &Path) -> Result<(&Path, String), DaemonError> {
    match (path.parent(), path.file_name()) {
        (Some(dir), Some(name)) => Ok((dir, name.to_string_lossy().into_owned())),
        _ => Err(DaemonError::LogFile {
            path: path.to_path_buf(),
            source: io::Error::new(io::ErrorKind::InvalidInput, "not a file's path"),
        }),
    }
}

/// Refuses `path` when it is a symbolic link (whatever it is otherwise, or if it is missing).
pub(crate) fn refuse_link(path: &Path) -> Result<(), DaemonError> {
    match is_link(path) {
        true => Err(DaemonError::LogLink {
            path: path.to_path_buf(),
        }),
        false => Ok(()),
    }
}

/// Creates the directory `path`, or checks that the one there is a directory and no link.
pub(crate) fn real_dir(path: &Path) -> Result<(), DaemonError> {
    match std::fs::create_dir(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
            refuse_link(path)?;
            match std::fs::metadata(path) {
                Ok(m) if m.is_dir() => Ok(()),
                _ => Err(DaemonError::LogFile {
                    path: path.to_path_buf(),
                    source: io::Error::new(io::ErrorKind::AlreadyExists, "not a directory"),
                }),
            }
        }
        Err(source) => Err(DaemonError::LogFile {
            path: path.to_path_buf(),
            source,
        }),
    }
}

/// A new directory in `parent` named `stem`, or `stem-1`, `stem-2`, ... when taken; its path.
pub(crate) fn new_dir(parent: &Path, stem: &str) -> io::Result<PathBuf> {
    let mut n = 0;
    loop {
        let path = match n {
            0 => parent.join(stem),
            n => parent.join(format!("{stem}-{n}")),
        };
        match std::fs::create_dir(&path) {
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists && n < NAME_TRIES => n += 1,
            created => return created.map(|()| path),
        }
    }
}

/// Writes `bytes` into the new file `path` (refused if anything is there).
pub(crate) fn write_new(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut file = no_follow().write(true).create_new(true).open(path)?;
    file.write_all(bytes)
}

/// Writes `bytes` into `path`, replacing the file there (never a link).
pub(crate) fn write_over(path: &Path, bytes: &[u8]) -> Result<(), DaemonError> {
    let opened = no_follow()
        .write(true)
        .create(true)
        .truncate(true)
        .open(path);
    let mut file = opened.map_err(|e| open_error(path, e))?;
    file.write_all(bytes)
        .map_err(|source| DaemonError::LogWrite {
            path: path.to_path_buf(),
            source,
        })
}

/// Opens `dir/rel` for reading, refusing a link at any component of `rel` (directories
/// included).
pub(crate) fn open_read(dir: &Path, rel: &[&str]) -> io::Result<File> {
    let mut path = dir.to_path_buf();
    for (k, part) in rel.iter().enumerate() {
        path.push(part);
        if k + 1 < rel.len() && is_link(&path) {
            return Err(io::Error::from_raw_os_error(libc::ELOOP));
        }
    }
    no_follow().read(true).open(path)
}

/// The live-diagnosis history of the valve named `valve` in the log directory `dir`.
pub(crate) fn history_file(dir: &Path, valve: &str) -> PathBuf {
    dir.join(format!("diagnosis-{valve}.jsonl"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::symlink;

    #[test]
    fn a_new_file_appears_with_its_header_under_the_first_free_name() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("a.csv"), "taken").unwrap();
        // A temporary file a crash left behind is replaced.
        std::fs::write(dir.path().join("x.part"), "stale").unwrap();
        let names = ["a.csv", "a-1.csv"].map(String::from);
        let (path, mut file) = create_with_header(dir.path(), "x.part", names, b"h\n").unwrap();
        assert_eq!(path, dir.path().join("a-1.csv"));
        assert_eq!(std::fs::read(&path).unwrap(), b"h\n");
        file.write_all(b"1\n").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"h\n1\n");
        let mut left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        left.sort();
        assert_eq!(left, ["a-1.csv", "a.csv"]);
        let full = create_with_header(dir.path(), "x.part", ["a.csv".into()], b"h\n");
        assert!(matches!(full, Err(DaemonError::LogFile { .. })));
        assert!(!dir.path().join("x.part").exists());
    }

    #[test]
    fn a_history_is_appended_to_after_its_last_whole_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("h.csv");
        let (mut f, size) = open_history(&path, b"t,x\n").unwrap();
        assert_eq!(size, 4);
        f.write_all(b"1,2\n3,").unwrap();
        drop(f);
        let (mut f, size) = open_history(&path, b"t,x\n").unwrap();
        assert_eq!(size, 8);
        f.write_all(b"5,6\n").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "t,x\n1,2\n5,6\n");
        // Another header: refused, the file untouched.
        let e = open_history(&path, b"t,y\n").unwrap_err();
        assert!(matches!(e, DaemonError::LogHeader { .. }), "{e}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "t,x\n1,2\n5,6\n");
        // No header (JSON lines): created empty.
        let (_, size) = open_history(&dir.path().join("h.jsonl"), b"").unwrap();
        assert_eq!(size, 0);
    }

    #[test]
    fn links_are_refused_and_their_targets_untouched() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("target");
        std::fs::write(&target, "keep").unwrap();
        let link = dir.path().join("link");
        symlink(&target, &link).unwrap();
        let e = open_history(&link, b"h\n").unwrap_err();
        assert!(
            matches!(&e, DaemonError::LogLink { path } if *path == link),
            "{e}"
        );
        assert!(e.to_string().contains("does not follow links"), "{e}");
        let e = create_with_header(dir.path(), "link", ["new".into()], b"h\n").unwrap_err();
        assert!(matches!(e, DaemonError::LogLink { .. }), "{e}");
        assert!(matches!(
            write_over(&link, b"x"),
            Err(DaemonError::LogLink { .. })
        ));
        assert!(write_new(&link, b"x").is_err());
        assert!(matches!(real_dir(&link), Err(DaemonError::LogLink { .. })));
        assert!(open_read(dir.path(), &["link"]).is_err());
        std::fs::create_dir(dir.path().join("d")).unwrap();
        symlink(dir.path(), dir.path().join("d/up")).unwrap();
        assert!(open_read(dir.path(), &["d", "up", "target"]).is_err());
        assert!(open_read(dir.path(), &["target"]).is_ok());
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "keep");
        assert!(!dir.path().join("new").exists());
    }
}
