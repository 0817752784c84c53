//! Output files are written to a temporary name next to the target and renamed, so an
//! interrupted run never leaves a partial file. Input files are read only when they are regular
//! files, up to a stated size ([`read_input_file`]): a device (`/dev/zero`), a pipe or a folder
//! named as a lens file or table would otherwise be read without bound or block.

use crate::error::{Error, Result};
use std::io::{Read, Write};
use std::path::Path;

/// The largest text lens file (TOML, .dat, .zmx, a lentil database) read: 64 MiB.
pub const MAX_LENS_FILE_BYTES: u64 = 64 << 20;

/// Reads `path` if it is a regular file (after following links) of at most `max_bytes`; `what`
/// names the kind of file in the error ("lens file", "LRTF table").
pub fn read_input_file(path: &Path, max_bytes: u64, what: &str) -> Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        let m = format!("a {what} must be a regular file (this is a folder, device or pipe)");
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::InvalidInput, m)));
    }
    if meta.len() > max_bytes {
        let m = format!("{} bytes is more than the {max_bytes} a {what} may have", meta.len());
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::InvalidData, m)));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    // `take`: a file that grows while it is read is still bounded
    std::fs::File::open(path)
        .and_then(|f| f.take(max_bytes + 1).read_to_end(&mut bytes))
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > max_bytes {
        let m = format!("more than the {max_bytes} bytes a {what} may have");
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::InvalidData, m)));
    }
    Ok(bytes)
}

/// Writes `bytes` to `path` atomically (temporary file in the same directory, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::io(path, e));
    }
    Ok(())
}
