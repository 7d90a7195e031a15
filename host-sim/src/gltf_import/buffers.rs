//! The bytes behind a glTF document: buffers from the GLB chunk, `data:` URIs or files next
//! to the document (read bounded), and the range checks that let the accessor readers run
//! without panicking.

use std::path::Path;

use gltf::buffer::Source;
use gltf::Document;

use super::base64;
use super::error::GltfError;
use crate::limits::{read_bounded, MAX_MESH_BYTES, MAX_TEXTURE_BYTES};

/// Every buffer's bytes, by index.
pub fn load_buffers(
    doc: &Document,
    blob: Option<Vec<u8>>,
    file: &str,
    base_dir: &Path,
) -> Result<Vec<Vec<u8>>, GltfError> {
    let mut blob = blob;
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let i = buffer.index();
        let err = |message: String| GltfError::Buffer {
            file: file.to_string(),
            buffer: i,
            message,
        };
        let data = match buffer.source() {
            Source::Bin => blob
                .take()
                .ok_or_else(|| err("refers to the GLB binary chunk, which is missing".into()))?,
            Source::Uri(uri) => {
                uri_bytes(uri, base_dir, MAX_MESH_BYTES, "glTF buffer").map_err(|e| match e {
                    UriError::Read(r) => GltfError::Read(r),
                    UriError::Malformed(m) => err(m),
                })?
            }
        };
        if data.len() < buffer.length() {
            return Err(err(format!(
                "byteLength is {} but only {} bytes are there",
                buffer.length(),
                data.len()
            )));
        }
        out.push(data);
    }
    Ok(out)
}

pub enum UriError {
    Read(crate::limits::ReadError),
    Malformed(String),
}

/// The bytes of a `data:` URI (base64 only) or of a file relative to `base_dir`.
pub fn uri_bytes(
    uri: &str,
    base_dir: &Path,
    limit: u64,
    what: &'static str,
) -> Result<Vec<u8>, UriError> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, payload) = rest
            .split_once(";base64,")
            .ok_or_else(|| UriError::Malformed("data: URI is not base64".into()))?;
        if payload.len() as u64 > limit.saturating_mul(4) / 3 + 4 {
            return Err(UriError::Malformed(format!(
                "data: URI over the {limit}-byte limit"
            )));
        }
        return base64::decode(payload)
            .ok_or_else(|| UriError::Malformed("data: URI has invalid base64".into()));
    }
    let name =
        percent_decode(uri).ok_or_else(|| UriError::Malformed(format!("bad URI `{uri}`")))?;
    read_bounded(&base_dir.join(name), limit, what).map_err(UriError::Read)
}

/// The bytes of an image: a buffer view's range or a URI.
pub fn image_bytes(
    source: gltf::image::Source<'_>,
    buffers: &[Vec<u8>],
    base_dir: &Path,
) -> Result<Vec<u8>, UriError> {
    match source {
        gltf::image::Source::View { view, .. } => view_slice(&view, buffers)
            .map(<[u8]>::to_vec)
            .ok_or_else(|| UriError::Malformed("its buffer view is out of range".into())),
        gltf::image::Source::Uri { uri, .. } => {
            uri_bytes(uri, base_dir, MAX_TEXTURE_BYTES, "glTF image")
        }
    }
}

fn percent_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

pub fn view_slice<'b>(view: &gltf::buffer::View<'_>, buffers: &'b [Vec<u8>]) -> Option<&'b [u8]> {
    let data = buffers.get(view.buffer().index())?;
    let end = view.offset().checked_add(view.length())?;
    data.get(view.offset()..end)
}

/// Checks that `accessor` (and its sparse parts) lies within its buffer views and buffers.
pub fn check_accessor(
    accessor: &gltf::Accessor<'_>,
    buffers: &[Vec<u8>],
    file: &str,
) -> Result<(), GltfError> {
    let err = |message: String| GltfError::Accessor {
        file: file.to_string(),
        path: format!("accessors[{}]", accessor.index()),
        message,
    };
    if accessor.count() == 0 {
        return Err(err("count is 0".into()));
    }
    if let Some(view) = accessor.view() {
        check_range(
            &view,
            accessor.offset(),
            accessor.count(),
            accessor.size(),
            buffers,
        )
        .map_err(err)?;
    }
    if let Some(sparse) = accessor.sparse() {
        if sparse.count() == 0 {
            return Err(err("sparse.count is 0".into()));
        }
        let idx = sparse.indices();
        check_range(
            &idx.view(),
            idx.offset(),
            sparse.count(),
            idx.index_type().size(),
            buffers,
        )
        .map_err(|m| err(format!("sparse.indices: {m}")))?;
        let val = sparse.values();
        check_range(
            &val.view(),
            val.offset(),
            sparse.count(),
            accessor.size(),
            buffers,
        )
        .map_err(|m| err(format!("sparse.values: {m}")))?;
    }
    Ok(())
}

fn check_range(
    view: &gltf::buffer::View<'_>,
    offset: usize,
    count: usize,
    elem: usize,
    buffers: &[Vec<u8>],
) -> Result<(), String> {
    let data = view_slice(view, buffers).ok_or_else(|| {
        format!(
            "bufferViews[{}] (offset {}, length {}) reaches past its buffer",
            view.index(),
            view.offset(),
            view.length()
        )
    })?;
    let stride = view.stride().unwrap_or(elem);
    let end = stride
        .checked_mul(count - 1)
        .and_then(|v| v.checked_add(offset))
        .and_then(|v| v.checked_add(elem));
    match end {
        Some(end) if end <= data.len() && stride >= elem => Ok(()),
        _ => Err(format!(
            "{count} elements of {elem} bytes (stride {stride}) from offset {offset} do not fit \
             bufferViews[{}] ({} bytes)",
            view.index(),
            data.len()
        )),
    }
}
