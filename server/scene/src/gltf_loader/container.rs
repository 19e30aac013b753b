//! The file: GLB chunks, the JSON document with its version and extensions, buffers from
//! the BIN chunk, `data:` URIs or files next to the document.

use super::*;

/// Splits a GLB container into its JSON chunk and optional BIN chunk.
pub(super) fn split_glb(bytes: &[u8]) -> Result<(&[u8], Option<&[u8]>), LoadError> {
    let u32_at = |offset: usize| {
        bytes
            .get(offset..offset.checked_add(4)?)
            .and_then(|b| <[u8; 4]>::try_from(b).ok())
            .map(u32::from_le_bytes)
    };
    let (Some(version), Some(length)) = (u32_at(4), u32_at(8)) else {
        return Err(LoadError::Glb(format!(
            "file is {} bytes, shorter than the 12-byte header",
            bytes.len()
        )));
    };
    if version != 2 {
        return Err(LoadError::Glb(format!(
            "container version {version} is not supported (only 2)"
        )));
    }
    let length = length as usize;
    if length < 12 {
        return Err(LoadError::Glb(format!(
            "header length {length} is smaller than the header itself"
        )));
    }
    if length > bytes.len() {
        return Err(LoadError::Glb(format!(
            "header says the file is {length} bytes, but only {} are present (truncated?)",
            bytes.len()
        )));
    }
    let mut json = None;
    let mut bin = None;
    let mut offset = 12;
    let mut chunk = 0;
    while offset < length {
        let header = u32_at(offset).zip(bytes.get(offset + 4..offset + 8));
        let Some((chunk_length, kind)) = header.filter(|_| offset + 8 <= length) else {
            return Err(LoadError::Glb(format!(
                "chunk {chunk} at byte {offset}: header is truncated"
            )));
        };
        let start = offset + 8;
        let data = start
            .checked_add(chunk_length as usize)
            .filter(|&end| end <= length)
            .and_then(|end| bytes.get(start..end));
        let Some(data) = data else {
            return Err(LoadError::Glb(format!(
                "chunk {chunk} at byte {offset}: length {chunk_length} runs past the end of \
                 the file ({length} bytes)"
            )));
        };
        match (chunk, kind) {
            (0, b"JSON") => json = Some(data),
            (0, _) => {
                return Err(LoadError::Glb(format!(
                    "first chunk has type {:?}, expected JSON",
                    String::from_utf8_lossy(kind)
                )))
            }
            (1, b"BIN\0") => bin = Some(data),
            // The spec requires loaders to skip chunks of unknown type.
            _ => {}
        }
        offset = start + data.len();
        chunk += 1;
    }
    let json = json.ok_or_else(|| LoadError::Glb(String::from("file has no JSON chunk")))?;
    Ok((json, bin))
}

/// Parses and validates the JSON document.
pub(super) fn parse_document(json_bytes: &[u8]) -> Result<json::Root, LoadError> {
    check_version_and_extensions(json_bytes)?;
    let root: json::Root = serde_json::from_slice(json_bytes).map_err(LoadError::Json)?;
    // gltf-json's validation indexes `accessors` with the POSITION attribute unchecked.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let position = primitive
                .attributes
                .get(&Checked::Valid(Semantic::Positions));
            if let Some(accessor) = position.filter(|a| a.value() >= root.accessors.len()) {
                return Err(invalid(
                    format!("{} primitive {p}", named("mesh", m, mesh.name.as_deref())),
                    format!("POSITION accessor {} does not exist", accessor.value()),
                ));
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(&root, json::Path::new, &mut |path, error| {
        let path = path();
        // Bounds are computed from the vertices, and many exporters omit POSITION min/max.
        let position_bounds = path.as_str().ends_with("[\"POSITION\"].min")
            || path.as_str().ends_with("[\"POSITION\"].max");
        if !(position_bounds && error == json::validation::Error::Missing) {
            errors.push(format!("{path}: {error}"));
        }
    });
    if !errors.is_empty() {
        let total = errors.len();
        errors.truncate(MAX_VALIDATION_ERRORS_SHOWN);
        let mut message = errors.join("; ");
        if total > MAX_VALIDATION_ERRORS_SHOWN {
            message.push_str(&format!(
                " (and {} more)",
                total - MAX_VALIDATION_ERRORS_SHOWN
            ));
        }
        return Err(LoadError::Validation(message));
    }
    Ok(root)
}

/// Checks the version and required extensions on the untyped JSON, so that a glTF 1.0 file or
/// one relying on an unsupported extension gets that message rather than a type error from
/// the typed parse.
pub(super) fn check_version_and_extensions(json_bytes: &[u8]) -> Result<(), LoadError> {
    let value: serde_json::Value = serde_json::from_slice(json_bytes).map_err(LoadError::Json)?;
    if let Some(version) = value
        .get("asset")
        .and_then(|asset| asset.get("version"))
        .and_then(serde_json::Value::as_str)
    {
        if !version.starts_with("2.") {
            return Err(invalid(
                "asset.version",
                format!("'{version}' is not supported (only glTF 2.x)"),
            ));
        }
    }
    if let Some(required) = value
        .get("extensionsRequired")
        .and_then(serde_json::Value::as_array)
    {
        for extension in required.iter().filter_map(serde_json::Value::as_str) {
            if !SUPPORTED_EXTENSIONS.contains(&extension) {
                return Err(LoadError::UnsupportedExtension(extension.to_owned()));
            }
        }
    }
    Ok(())
}

pub(super) fn load_buffers<'a>(
    root: &json::Root,
    bin: Option<&'a [u8]>,
    base_dir: Option<&Path>,
) -> Result<Vec<Cow<'a, [u8]>>, LoadError> {
    let mut buffers = Vec::with_capacity(root.buffers.len());
    for (index, buffer) in root.buffers.iter().enumerate() {
        let part = named("buffer", index, buffer.name.as_deref());
        let data: Cow<'a, [u8]> = match (&buffer.uri, bin) {
            (Some(uri), _) => Cow::Owned(read_uri(uri, base_dir, &part)?),
            (None, Some(bin)) if index == 0 => Cow::Borrowed(bin),
            (None, None) if index == 0 => {
                return Err(invalid(
                    part,
                    "has no uri, and there is no GLB binary chunk",
                ))
            }
            (None, _) => {
                return Err(invalid(
                    part,
                    "has no uri; only buffer 0 of a .glb may refer to the binary chunk",
                ))
            }
        };
        let declared = buffer.byte_length.0;
        let available = data.len();
        // Trimming to the declared length makes views reaching into GLB padding an error.
        let data = match data {
            Cow::Borrowed(d) => usize::try_from(declared)
                .ok()
                .and_then(|n| d.get(..n))
                .map(Cow::Borrowed),
            Cow::Owned(mut d) => usize::try_from(declared)
                .ok()
                .filter(|&n| n <= d.len())
                .map(|n| {
                    d.truncate(n);
                    Cow::Owned(d)
                }),
        };
        let data = data.ok_or_else(|| {
            invalid(
                &part,
                format!("byteLength is {declared}, but only {available} bytes are available"),
            )
        })?;
        buffers.push(data);
    }
    Ok(buffers)
}

/// Reads the bytes a buffer or image URI refers to: a base64 `data:` URI or a relative path.
pub(super) fn read_uri(
    uri: &str,
    base_dir: Option<&Path>,
    part: &str,
) -> Result<Vec<u8>, LoadError> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let Some((media, payload)) = rest.split_once(',') else {
            return Err(invalid(part, "data URI has no ',' before its payload"));
        };
        if !media.ends_with(";base64") {
            return Err(invalid(part, "data URI is not base64-encoded"));
        }
        return base64_decode(payload)
            .map_err(|message| invalid(part, format!("data URI: {message}")));
    }
    if has_scheme(uri) {
        return Err(invalid(
            part,
            format!("URI '{uri}' has an unsupported scheme (only relative paths and data: URIs)"),
        ));
    }
    let relative =
        percent_decode(uri).map_err(|message| invalid(part, format!("URI '{uri}': {message}")))?;
    let Some(base_dir) = base_dir else {
        return Err(invalid(
            part,
            format!(
                "refers to external file '{uri}', but the glTF was loaded from memory without \
                 a base directory"
            ),
        ));
    };
    let path = base_dir.join(relative);
    fs::read(&path).map_err(|error| LoadError::External {
        part: part.to_owned(),
        uri: uri.to_owned(),
        path,
        error,
    })
}

/// Whether a URI starts with an RFC 3986 scheme ("http:", "file:"). Single letters are not
/// treated as schemes so that Windows drive paths stay paths.
pub(super) fn has_scheme(uri: &str) -> bool {
    let Some((scheme, _)) = uri.split_once(':') else {
        return false;
    };
    scheme.len() > 1
        && scheme.starts_with(|c: char| c.is_ascii_alphabetic())
        && scheme
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.'))
}

pub(super) fn percent_decode(text: &str) -> Result<String, String> {
    let mut out = Vec::with_capacity(text.len());
    let mut bytes = text.bytes();
    while let Some(b) = bytes.next() {
        if b == b'%' {
            let hex = [bytes.next(), bytes.next()];
            let digits = hex.map(|h| h.and_then(|h| (h as char).to_digit(16)));
            let [Some(hi), Some(lo)] = digits else {
                return Err(String::from("invalid percent escape"));
            };
            out.push((hi * 16 + lo) as u8);
        } else {
            out.push(b);
        }
    }
    String::from_utf8(out).map_err(|_| String::from("percent escapes do not decode to UTF-8"))
}

pub(super) fn base64_decode(text: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(text.len() / 4 * 3);
    let mut acc = 0u32;
    let mut bits = 0u32;
    let mut padding = false;
    for (offset, c) in text.bytes().enumerate() {
        let value = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => {
                padding = true;
                continue;
            }
            c if c.is_ascii_whitespace() => continue,
            c => {
                return Err(format!(
                    "invalid base64 character {:?} at offset {offset}",
                    c as char
                ))
            }
        };
        if padding {
            return Err(format!(
                "base64 data continues after '=' padding at offset {offset}"
            ));
        }
        acc = (acc << 6) | u32::from(value);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}
