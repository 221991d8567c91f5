//! One daemon per state folder: a second `visobjd run` on the same folder (a technician
//! starting it by hand while the service runs) must stop before it sends a single frame,
//! since it would send with the running daemon's sACN CID and then terminate its stream.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::Path;

/// The name of the lock file in the state folder.
const LOCK_FILE: &str = "visobjd.lock";

/// An exclusive advisory lock on a state folder, held until dropped (or the process ends,
/// however it ends: the kernel releases it, so a crash never leaves a stale lock).
#[derive(Debug)]
pub struct FolderLock {
    _file: File,
}

impl FolderLock {
    /// Takes the lock on `dir` (which must exist) and records this process's id in it.
    /// The error is a sentence naming the folder and, when it can be read, the holder.
    pub fn take(dir: &Path) -> Result<FolderLock, String> {
        let path = dir.join(LOCK_FILE);
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| {
                format!(
                    "state folder {}: cannot open {LOCK_FILE}: {e}",
                    dir.display()
                )
            })?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                let mut holder = String::new();
                let _ = file.read_to_string(&mut holder);
                let holder = holder.trim();
                let who = if holder.is_empty() {
                    "another visobjd".to_string()
                } else {
                    format!("another visobjd (pid {holder})")
                };
                return Err(format!(
                    "state folder {} is in use by {who}: stop it first (systemctl stop visobjd), \
                     or give this one its own state_dir and ports",
                    dir.display()
                ));
            }
            Err(TryLockError::Error(e)) => {
                return Err(format!(
                    "state folder {}: cannot lock {LOCK_FILE}: {e}",
                    dir.display()
                ));
            }
        }
        // The pid is for the message above only: the lock itself is the kernel's.
        let pid = std::process::id().to_string();
        file.set_len(0)
            .and_then(|()| file.rewind())
            .and_then(|()| file.write_all(pid.as_bytes()))
            .map_err(|e| {
                format!(
                    "state folder {}: cannot write {LOCK_FILE}: {e}",
                    dir.display()
                )
            })?;
        Ok(FolderLock { _file: file })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_on_the_folder_is_refused_and_names_the_holder() {
        let dir = std::env::temp_dir().join(format!("visobjd-lock-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let first = FolderLock::take(&dir).unwrap();
        let err = FolderLock::take(&dir).unwrap_err();
        assert!(err.contains("in use by another visobjd"), "{err}");
        assert!(err.contains(&std::process::id().to_string()), "{err}");
        drop(first);
        FolderLock::take(&dir).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
