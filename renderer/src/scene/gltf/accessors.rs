//! Buffers, URIs (data URIs, relative files) and accessor decoding with checked byte ranges.

use super::{named, Loader};
use crate::Result;
use gltf::accessor::{DataType, Dimensions};
use std::path::PathBuf;

/// The largest image file a glTF scene may reference (the decoder's own limits guard the pixels).
pub(super) const MAX_IMAGE_FILE_BYTES: u64 = crate::limits::MAX_FILE_BYTES;

impl Loader<'_> {
    // ---------------------------------------------------------------- buffers and images

    /// Reads a URI: a data URI (base64) or a file relative to the glTF file.
    /// The bytes a URI names: data URIs, or regular files (a device, pipe or folder is refused).
    /// At most `max_bytes` are read: a longer file is cut there when `truncate` (a buffer, of
    /// which only byteLength counts), else refused (an image).
    pub(super) fn read_uri(&self, uri: &str, max_bytes: u64, truncate: bool) -> std::result::Result<Vec<u8>, String> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let (_, data) = rest.split_once(";base64,").ok_or("data URI is not base64")?;
            return base64_decode(data).ok_or_else(|| "data URI has invalid base64".to_string());
        }
        let path: PathBuf = if let Some(rest) = uri.strip_prefix("file://") {
            PathBuf::from(percent_decode(rest))
        } else if uri.split('/').next().is_some_and(|first| first.contains(':') && first.len() > 2) {
            return Err(format!("URI scheme of '{uri}' is not supported (files and data URIs only)"));
        } else {
            let base = self.base.ok_or("external file references need a base directory")?;
            base.join(percent_decode(uri))
        };
        let meta = std::fs::metadata(&path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        if !meta.is_file() {
            return Err(format!("{} is not a regular file (a device, pipe or folder)", path.display()));
        }
        if meta.len() > max_bytes && !truncate {
            return Err(format!("{} is {} bytes, more than the {max_bytes}-byte limit", path.display(), meta.len()));
        }
        let mut data = Vec::with_capacity(meta.len().min(max_bytes) as usize);
        std::io::Read::read_to_end(
            &mut std::io::Read::take(
                std::fs::File::open(&path).map_err(|e| format!("cannot read {}: {e}", path.display()))?,
                max_bytes,
            ),
            &mut data,
        )
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        Ok(data)
    }

    pub(super) fn load_buffers(&mut self, mut blob: Option<Vec<u8>>) -> Result<()> {
        let doc = self.doc;
        let buffers: Vec<_> = doc.buffers().collect();
        // Up front: the declared buffer sizes must fit the memory available.
        let declared: u64 = buffers.iter().map(|b| b.length() as u64).sum();
        if let Err(budget) = crate::limits::check_memory(declared) {
            return Err(self.error(
                "buffers",
                format!(
                    "declare {} in all (byteLength), {}",
                    crate::limits::format_bytes(declared),
                    crate::limits::over_budget(budget)
                ),
            ));
        }
        for b in buffers {
            let loc = named("buffer", b.index(), b.name());
            let mut data = match b.source() {
                gltf::buffer::Source::Bin => {
                    blob.take().ok_or_else(|| self.error(&loc, "refers to the GLB binary chunk, which is missing"))?
                }
                gltf::buffer::Source::Uri(uri) => {
                    // only what byteLength declares is read (the rest would be dropped anyway)
                    self.read_uri(uri, b.length() as u64, true).map_err(|m| self.error(&loc, m))?
                }
            };
            if data.len() < b.length() {
                return Err(self.error(
                    &loc,
                    format!("has {} bytes but byteLength is {} (truncated file?)", data.len(), b.length()),
                ));
            }
            data.truncate(b.length());
            self.buffers.push(data);
        }
        Ok(())
    }

    /// The bytes of a buffer view, checked against its buffer.
    pub(super) fn view_bytes(&self, view: &gltf::buffer::View) -> std::result::Result<&[u8], String> {
        let buf = self.buffers.get(view.buffer().index()).ok_or("buffer not loaded")?;
        let end = view.offset().checked_add(view.length()).ok_or("bufferView range overflows")?;
        buf.get(view.offset()..end).ok_or_else(|| {
            format!(
                "bufferView {} (bytes {}..{end}) lies outside buffer {} ({} bytes)",
                view.index(),
                view.offset(),
                view.buffer().index(),
                buf.len()
            )
        })
    }
}

// -------------------------------------------------------------------- accessor decoding

fn component_size(t: DataType) -> usize {
    match t {
        DataType::I8 | DataType::U8 => 1,
        DataType::I16 | DataType::U16 => 2,
        DataType::U32 | DataType::F32 => 4,
    }
}

/// Reads one component at `bytes[0..size]` (little endian), normalized if asked.
fn read_component(bytes: &[u8], t: DataType, normalized: bool) -> f64 {
    let b = |i: usize| bytes.get(i).copied().unwrap_or(0);
    match t {
        DataType::I8 => {
            let v = b(0) as i8 as f64;
            if normalized {
                (v / 127.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U8 => {
            let v = b(0) as f64;
            if normalized {
                v / 255.0
            } else {
                v
            }
        }
        DataType::I16 => {
            let v = i16::from_le_bytes([b(0), b(1)]) as f64;
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U16 => {
            let v = u16::from_le_bytes([b(0), b(1)]) as f64;
            if normalized {
                v / 65535.0
            } else {
                v
            }
        }
        DataType::U32 => {
            let v = u32::from_le_bytes([b(0), b(1), b(2), b(3)]) as f64;
            if normalized {
                v / 4294967295.0
            } else {
                v
            }
        }
        DataType::F32 => f32::from_le_bytes([b(0), b(1), b(2), b(3)]) as f64,
    }
}

/// How the elements of an accessor (or of its sparse parts) are laid out.
#[derive(Clone, Copy)]
struct Layout {
    /// Components per element.
    ncomp: usize,
    /// Component type.
    t: DataType,
    /// Normalized integers.
    normalized: bool,
    /// Tightly packed (sparse data), ignoring the view's byteStride.
    tight: bool,
}

/// Reads `count` elements from a view at `offset`, with checked ranges.
fn read_elements(
    loader: &Loader,
    view: &gltf::buffer::View,
    offset: usize,
    count: usize,
    layout: Layout,
) -> std::result::Result<Vec<f64>, String> {
    let Layout { ncomp, t, normalized, tight } = layout;
    let bytes = loader.view_bytes(view)?;
    let csize = component_size(t);
    let esize = csize * ncomp;
    let stride = if tight { esize } else { view.stride().unwrap_or(esize) };
    if stride < esize {
        return Err(format!("byteStride {stride} is smaller than the element size {esize}"));
    }
    if count == 0 {
        return Ok(Vec::new());
    }
    let last = (count - 1)
        .checked_mul(stride)
        .and_then(|x| x.checked_add(offset))
        .and_then(|x| x.checked_add(esize))
        .ok_or("accessor range overflows")?;
    if last > bytes.len() {
        return Err(format!(
            "{count} elements at byteOffset {offset} (stride {stride}) need {last} bytes but bufferView {} has {}",
            view.index(),
            bytes.len()
        ));
    }
    let mut out = Vec::with_capacity(count * ncomp);
    for e in 0..count {
        let start = offset + e * stride;
        for c in 0..ncomp {
            let s = start + c * csize;
            out.push(read_component(&bytes[s..s + csize], t, normalized));
        }
    }
    Ok(out)
}

/// Decodes an accessor (any component type, strided, sparse) into `count × n` f64 values
/// returned as f32 for attributes; indices are exact in f64 before the conversion.
pub(super) fn read_accessor(loader: &Loader, acc: &gltf::Accessor) -> std::result::Result<Vec<f32>, String> {
    let v = read_accessor_f64(loader, acc)?;
    Ok(v.into_iter().map(|x| x as f32).collect())
}

fn read_accessor_f64(loader: &Loader, acc: &gltf::Accessor) -> std::result::Result<Vec<f64>, String> {
    let ncomp = match acc.dimensions() {
        Dimensions::Scalar => 1,
        Dimensions::Vec2 => 2,
        Dimensions::Vec3 => 3,
        Dimensions::Vec4 => 4,
        // a skin's inverse bind matrices (floats only: the spec's only type for them, and the
        // only matrix layout without column padding)
        Dimensions::Mat4 if acc.data_type() == DataType::F32 => 16,
        d => return Err(format!("matrix accessor type {d:?} of {:?} is not supported here", acc.data_type())),
    };
    let t = acc.data_type();
    let count = acc.count();
    let mut out = match acc.view() {
        Some(view) => {
            let layout = Layout { ncomp, t, normalized: acc.normalized(), tight: false };
            read_elements(loader, &view, acc.offset(), count, layout)?
        }
        None => {
            // Sparse-only (or empty) accessor: zeros. Bound the allocation by the buffer data.
            let total: usize = loader.buffers.iter().map(Vec::len).sum();
            if acc.sparse().is_none() && count > 0 {
                return Err("accessor has neither bufferView nor sparse data".into());
            }
            if count.saturating_mul(ncomp) > total.saturating_mul(8).max(1 << 20) {
                return Err(format!("accessor count {count} is implausibly large"));
            }
            vec![0.0; count * ncomp]
        }
    };
    if let Some(sparse) = acc.sparse() {
        let n = sparse.count();
        let idx = sparse.indices();
        let it = match idx.index_type() {
            gltf::accessor::sparse::IndexType::U8 => DataType::U8,
            gltf::accessor::sparse::IndexType::U16 => DataType::U16,
            gltf::accessor::sparse::IndexType::U32 => DataType::U32,
        };
        let layout = Layout { ncomp: 1, t: it, normalized: false, tight: true };
        let indices =
            read_elements(loader, &idx.view(), idx.offset(), n, layout).map_err(|m| format!("sparse indices: {m}"))?;
        let vals = sparse.values();
        let layout = Layout { ncomp, t, normalized: acc.normalized(), tight: true };
        let values =
            read_elements(loader, &vals.view(), vals.offset(), n, layout).map_err(|m| format!("sparse values: {m}"))?;
        for (k, &i) in indices.iter().enumerate() {
            let i = i as usize;
            if i >= count {
                return Err(format!("sparse index {i} is out of range for {count} elements"));
            }
            out[i * ncomp..(i + 1) * ncomp].copy_from_slice(&values[k * ncomp..(k + 1) * ncomp]);
        }
    }
    Ok(out)
}

// -------------------------------------------------------------------- URIs

/// Decodes standard or URL-safe base64 (padding optional, whitespace ignored).
pub(super) fn base64_decode(s: &str) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let mut acc: u32 = 0;
    let mut bits = 0u32;
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            b' ' | b'\n' | b'\r' | b'\t' => continue,
            _ => return None,
        };
        acc = (acc << 6) | v as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Some(out)
}

/// Decodes `%XX` escapes of a relative URI (invalid escapes are kept as written).
pub(super) fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            let hex = std::str::from_utf8(&b[i + 1..i + 3]).ok().and_then(|h| u8::from_str_radix(h, 16).ok());
            if let Some(v) = hex {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}
