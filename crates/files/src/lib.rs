//! Files in `state_dir` that must survive crashes and power cuts: written atomically
//! (temp file, fsync, rename, fsync of the folder), so a reader only ever sees the old or
//! the new version; a file that does not parse is moved aside, never deleted.

mod finite;
mod lock;

pub use lock::FolderLock;

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;
use serde::de::DeserializeOwned;

/// Writes `bytes` to `path` atomically.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_via_temp(path, bytes, |tmp, path| fs::rename(tmp, path))
}

/// Writes `bytes` to `path` atomically unless `path` exists: then nothing is written and
/// the error is `AlreadyExists`. The check and the write are one step (a hard link of the
/// temp file), so two writers of one name cannot replace each other's file.
pub fn write_new_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_via_temp(path, bytes, |tmp, path| {
        fs::hard_link(tmp, path)?;
        fs::remove_file(tmp)
    })
}

/// Writes `bytes` to a temp file beside `path`, syncs it, puts it in place with `place`,
/// then syncs the folder; the temp file is removed if any step fails.
fn write_via_temp(
    path: &Path,
    bytes: &[u8],
    place: impl FnOnce(&Path, &Path) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let dir = path.parent().unwrap_or(Path::new("."));
    fs::create_dir_all(dir)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    // Unique per process and call, so concurrent writers never share a temp file.
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = dir.join(format!(".{name}.{}.{n}.tmp", std::process::id()));
    let result = (|| {
        let mut f = File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        place(&tmp, path)?;
        // The new name is durable only once the folder is synced.
        File::open(dir)?.sync_all()
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Serialises `value` as pretty JSON and writes it atomically. A value holding a number
/// that is not finite is refused (`InvalidData`, naming where it sits) and nothing is
/// written: JSON would hold `null` there, and the next read would set the file aside.
pub fn save_json<T: Serialize>(path: &Path, value: &T) -> std::io::Result<()> {
    if let Some(what) = finite::first_non_finite(value) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("{what}, not a finite number: not written, the previous file is kept"),
        ));
    }
    let text = serde_json::to_vec_pretty(value).map_err(std::io::Error::other)?;
    write_atomic(path, &text)
}

/// What reading a state file found.
#[derive(Debug)]
pub enum Loaded<T> {
    /// The file parsed.
    Ok(T),
    /// There is no file (a first start).
    Missing,
    /// The file was unreadable or corrupt and was moved to the returned path.
    MovedAside(PathBuf, String),
}

/// Reads a JSON state file. A file that does not parse is renamed to
/// `NAME.corrupt-<unix seconds>` beside it, with the error logged, so nothing is lost and
/// the daemon can start.
pub fn load_json<T: DeserializeOwned>(path: &Path) -> Loaded<T> {
    let bytes = match fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Loaded::Missing,
        Err(e) => return move_aside(path, format!("cannot read it: {e}")),
    };
    match serde_json::from_slice(&bytes) {
        Ok(v) => Loaded::Ok(v),
        Err(e) => move_aside(path, format!("it is corrupt: {e}")),
    }
}

fn move_aside<T>(path: &Path, why: String) -> Loaded<T> {
    match keep_aside(path, &why) {
        Ok(aside) => Loaded::MovedAside(aside, why),
        Err(e) => {
            tracing::error!(
                "{}: {why}; could not move it aside ({e}), started without it",
                path.display()
            );
            Loaded::MovedAside(path.to_path_buf(), why)
        }
    }
}

/// Renames a bad state file to `NAME.corrupt-<unix seconds>` beside it and logs why, so a
/// person can inspect or restore it; returns the new path.
pub fn keep_aside(path: &Path, why: &str) -> std::io::Result<PathBuf> {
    let aside = aside_path(path, "corrupt");
    fs::rename(path, &aside)?;
    tracing::error!(
        "{}: {why}; kept it as {} and carried on without it",
        path.display(),
        aside.display()
    );
    Ok(aside)
}

/// Copies a state file that was only partly restored to `NAME.partial-<unix seconds>`
/// beside it before the daemon's next write replaces it, so what could not be brought
/// back (objectives, locks on groups the scene no longer has) is not lost.
pub fn keep_copy(path: &Path) -> std::io::Result<PathBuf> {
    let aside = aside_path(path, "partial");
    fs::copy(path, &aside)?;
    Ok(aside)
}

/// `NAME.<tag>-<unix seconds>` beside `path`.
fn aside_path(path: &Path, tag: &str) -> PathBuf {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let mut aside = path.as_os_str().to_owned();
    aside.push(format!(".{tag}-{secs}"));
    PathBuf::from(aside)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("visobjd-state-{}-{name}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temp_files() {
        let d = dir("atomic");
        let p = d.join("live.json");
        save_json(&p, &vec![1, 2, 3]).unwrap();
        save_json(&p, &vec![4, 5]).unwrap();
        match load_json::<Vec<u32>>(&p) {
            Loaded::Ok(v) => assert_eq!(v, vec![4, 5]),
            other => panic!("{other:?}"),
        }
        let names: Vec<_> = fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("live.json")]);
    }

    #[test]
    fn a_new_write_never_replaces_and_leaves_no_temp_files() {
        let d = dir("new");
        let p = d.join("ref.png");
        write_new_atomic(&p, b"first").unwrap();
        let again = write_new_atomic(&p, b"second").unwrap_err();
        assert_eq!(again.kind(), std::io::ErrorKind::AlreadyExists);
        assert_eq!(fs::read(&p).unwrap(), b"first");
        // Racing writers of one name: exactly one wins, whole.
        let q = d.join("race.png");
        let wins = std::thread::scope(|sc| {
            let writers: Vec<_> = (0..8u8)
                .map(|i| {
                    let q = &q;
                    sc.spawn(move || write_new_atomic(q, &[i; 64]).is_ok())
                })
                .collect();
            writers
                .into_iter()
                .filter_map(|w| w.join().ok())
                .filter(|&won| won)
                .count()
        });
        assert_eq!(wins, 1);
        let won = fs::read(&q).unwrap();
        assert!(won.len() == 64 && won.iter().all(|&b| b == won[0]));
        let names: Vec<_> = fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 2, "{names:?}");
    }

    #[test]
    fn a_value_that_is_not_finite_is_not_written_and_the_file_stays() {
        let d = dir("finite");
        let p = d.join("live.json");
        save_json(&p, &vec![0.5f32, 1.0]).unwrap();
        let e = save_json(&p, &vec![0.5f32, f32::NAN]).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidData);
        assert!(
            e.to_string().starts_with("[1] is NaN, not a finite number"),
            "{e}"
        );
        match load_json::<Vec<f32>>(&p) {
            Loaded::Ok(v) => assert_eq!(v, vec![0.5, 1.0]),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn missing_is_missing_and_corrupt_is_kept_aside() {
        let d = dir("corrupt");
        let p = d.join("looks.json");
        assert!(matches!(load_json::<Vec<u32>>(&p), Loaded::Missing));
        fs::write(&p, b"{ not json").unwrap();
        match load_json::<Vec<u32>>(&p) {
            Loaded::MovedAside(aside, why) => {
                assert!(why.contains("corrupt"), "{why}");
                assert_eq!(fs::read(&aside).unwrap(), b"{ not json");
                assert!(!p.exists());
            }
            other => panic!("{other:?}"),
        }
    }
}
