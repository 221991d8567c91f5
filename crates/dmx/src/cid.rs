//! The sACN component identifier: made once and kept in `state_dir/cid`, so receivers
//! (and their priority merges) see the same source after a restart.

use std::fs;
use std::io;
use std::path::Path;

use uuid::Uuid;

/// Reads `state_dir/cid` (a UUID in text), or makes a random (v4) one and writes it
/// atomically. A file that does not hold a UUID is renamed aside to
/// `cid.corrupt-<unix time>`, with an error logged, and replaced.
pub(crate) fn load_or_create(state_dir: &Path) -> io::Result<Uuid> {
    let path = state_dir.join("cid");
    match fs::read(&path) {
        Ok(bytes) => {
            let parsed = std::str::from_utf8(&bytes)
                .ok()
                .and_then(|t| Uuid::parse_str(t.trim()).ok())
                .filter(|u| !u.is_nil());
            if let Some(cid) = parsed {
                return Ok(cid);
            }
            visobjd_files::keep_aside(
                &path,
                "the sACN CID file does not hold a UUID; a new CID is made (receivers will see a new source)",
            )?;
        }
        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
        Err(e) => return Err(e),
    }
    let cid = Uuid::new_v4();
    visobjd_files::write_atomic(&path, format!("{}\n", cid.hyphenated()).as_bytes())?;
    Ok(cid)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("visobjd-cid-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn made_once_and_kept() {
        let dir = temp_dir("kept");
        let a = load_or_create(&dir).expect("creates");
        let b = load_or_create(&dir).expect("loads");
        assert_eq!(a, b);
        assert_eq!(a.get_version_num(), 4);
        fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn corrupt_file_is_moved_aside() {
        let dir = temp_dir("corrupt");
        fs::create_dir_all(&dir).expect("mkdir");
        fs::write(dir.join("cid"), b"not a uuid\xff").expect("write");
        let cid = load_or_create(&dir).expect("replaces");
        assert!(!cid.is_nil());
        let moved: Vec<_> = fs::read_dir(&dir)
            .expect("list")
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().starts_with("cid.corrupt-"))
            .collect();
        assert_eq!(moved.len(), 1);
        assert_eq!(load_or_create(&dir).expect("loads"), cid);
        fs::remove_dir_all(&dir).ok();
    }
}
