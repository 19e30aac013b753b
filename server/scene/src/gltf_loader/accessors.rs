//! Accessors: typed elements read from buffer views, bounds-checked, sparse ones applied.

use super::*;

/// `len` bytes from `offset`, if they lie inside `bytes`.
pub(super) fn slice_at(bytes: &[u8], offset: u64, len: u64) -> Option<&[u8]> {
    let start = usize::try_from(offset).ok()?;
    let end = start.checked_add(usize::try_from(len).ok()?)?;
    bytes.get(start..end)
}

pub(super) fn le_bytes<const N: usize>(bytes: &[u8]) -> [u8; N] {
    let mut out = [0; N];
    for (o, b) in out.iter_mut().zip(bytes) {
        *o = *b;
    }
    out
}

/// Decodes one component as a float, applying glTF's normalisation rules for integer types.
pub(super) fn decode_float(component: ComponentType, normalized: bool, bytes: &[u8]) -> f32 {
    let (value, max) = match component {
        ComponentType::F32 => return f32::from_le_bytes(le_bytes(bytes)),
        ComponentType::I8 => (f32::from(i8::from_le_bytes(le_bytes(bytes))), 127.0),
        ComponentType::U8 => (f32::from(u8::from_le_bytes(le_bytes(bytes))), 255.0),
        ComponentType::I16 => (f32::from(i16::from_le_bytes(le_bytes(bytes))), 32767.0),
        ComponentType::U16 => (f32::from(u16::from_le_bytes(le_bytes(bytes))), 65535.0),
        ComponentType::U32 => (u32::from_le_bytes(le_bytes(bytes)) as f32, u32::MAX as f32),
    };
    if normalized {
        (value / max).max(-1.0)
    } else {
        value
    }
}

/// Decodes one unsigned integer component; other types are rejected before decoding.
pub(super) fn decode_index(component: ComponentType, bytes: &[u8]) -> u32 {
    match component {
        ComponentType::U8 => u32::from(u8::from_le_bytes(le_bytes(bytes))),
        ComponentType::U16 => u32::from(u16::from_le_bytes(le_bytes(bytes))),
        _ => u32::from_le_bytes(le_bytes(bytes)),
    }
}

pub(super) const INDEX_COMPONENTS: &[ComponentType] =
    &[ComponentType::U8, ComponentType::U16, ComponentType::U32];
pub(super) const ANY_COMPONENT: &[ComponentType] = &[
    ComponentType::I8,
    ComponentType::U8,
    ComponentType::I16,
    ComponentType::U16,
    ComponentType::U32,
    ComponentType::F32,
];

pub(super) fn check_count(
    actual: usize,
    expected: usize,
    part: &str,
    usage: &str,
) -> Result<(), LoadError> {
    if actual == expected {
        Ok(())
    } else {
        Err(invalid(
            part,
            format!("{usage} has {actual} elements, but POSITION has {expected}"),
        ))
    }
}

impl Loader<'_> {
    pub(super) fn read_floats(
        &self,
        accessor: usize,
        ty: Type,
        part: &str,
        usage: &str,
    ) -> Result<Vec<f32>, LoadError> {
        self.read_accessor(accessor, ty, ANY_COMPONENT, part, usage, decode_float)
    }

    /// Reads an accessor's elements (flattened components), including sparse substitution,
    /// checking every byte range against its buffer view and buffer.
    pub(super) fn read_accessor<T: Clone + Default>(
        &self,
        index: usize,
        ty: Type,
        components: &[ComponentType],
        part: &str,
        usage: &str,
        decode: impl Fn(ComponentType, bool, &[u8]) -> T,
    ) -> Result<Vec<T>, LoadError> {
        let Some(accessor) = self.root.accessors.get(index) else {
            return Err(invalid(
                part,
                format!("{usage} accessor {index} does not exist"),
            ));
        };
        let part = format!(
            "{part}: {usage} {}",
            named("accessor", index, accessor.name.as_deref())
        );
        let Checked::Valid(actual) = accessor.type_ else {
            return Err(invalid(part, "type is invalid"));
        };
        if actual != ty {
            return Err(invalid(
                part,
                format!("type is {actual:?}, but {usage} needs {ty:?}"),
            ));
        }
        let Checked::Valid(GenericComponentType(component)) = accessor.component_type else {
            return Err(invalid(part, "componentType is invalid"));
        };
        if !components.contains(&component) {
            return Err(invalid(
                part,
                format!("componentType {component:?} cannot be used for {usage}"),
            ));
        }
        let multiplicity = ty.multiplicity();
        let component_size = component.size();
        let element_size = (multiplicity * component_size) as u64;
        let count = accessor.count.0;
        let too_large = || invalid(&part, format!("count {count} is too large"));
        if accessor.buffer_view.is_none() {
            let unbacked = self.unbacked_elements.get().saturating_add(count);
            if unbacked > MAX_UNBACKED_ELEMENTS {
                return Err(invalid(
                    &part,
                    format!(
                        "has no buffer view, and with it the file's zero-filled accessors \
                         hold {unbacked} elements; at most {MAX_UNBACKED_ELEMENTS} are allowed"
                    ),
                ));
            }
            self.unbacked_elements.set(unbacked);
        }
        let values_len = usize::try_from(count)
            .ok()
            .and_then(|c| c.checked_mul(multiplicity))
            .ok_or_else(too_large)?;
        let mut values = match accessor.buffer_view {
            None => vec![T::default(); values_len],
            Some(view) => {
                let view = view.value();
                let (bytes, stride) = self.view_bytes(view, &part)?;
                let stride = stride.map_or(element_size, |s| s as u64);
                if stride < element_size {
                    return Err(invalid(
                        part,
                        format!(
                            "buffer view {view} has byteStride {stride}, smaller than one \
                             element ({element_size} bytes)"
                        ),
                    ));
                }
                let offset = accessor.byte_offset.map_or(0, |o| o.0);
                let end = match count.checked_sub(1) {
                    None => Some(offset),
                    Some(last) => stride
                        .checked_mul(last)
                        .and_then(|x| x.checked_add(offset))
                        .and_then(|x| x.checked_add(element_size)),
                };
                if end.is_none_or(|end| end > bytes.len() as u64) {
                    return Err(invalid(
                        part,
                        format!(
                            "{count} elements of {element_size} bytes (stride {stride}) from \
                             byte {offset} run past the end of buffer view {view} ({} bytes)",
                            bytes.len()
                        ),
                    ));
                }
                let mut values = Vec::with_capacity(values_len);
                for element in 0..count {
                    let start = offset + element * stride;
                    for c in 0..multiplicity {
                        let at = start + (c * component_size) as u64;
                        let b = slice_at(bytes, at, component_size as u64)
                            .ok_or_else(|| invalid(&part, format!("byte {at} is out of range")))?;
                        values.push(decode(component, accessor.normalized, b));
                    }
                }
                values
            }
        };
        if let Some(sparse) = &accessor.sparse {
            let sparse_count = sparse.count.0;
            if sparse_count > count {
                return Err(invalid(
                    part,
                    format!("sparse count {sparse_count} exceeds the accessor count {count}"),
                ));
            }
            let Checked::Valid(IndexComponentType(index_component)) = sparse.indices.component_type
            else {
                return Err(invalid(part, "sparse indices componentType is invalid"));
            };
            let index_size = index_component.size() as u64;
            let (index_bytes, _) = self.view_bytes(sparse.indices.buffer_view.value(), &part)?;
            let (value_bytes, _) = self.view_bytes(sparse.values.buffer_view.value(), &part)?;
            for k in 0..sparse_count {
                let index_at = k
                    .checked_mul(index_size)
                    .and_then(|x| x.checked_add(sparse.indices.byte_offset.0));
                let target = index_at
                    .and_then(|at| slice_at(index_bytes, at, index_size))
                    .map(|b| decode_index(index_component, b))
                    .ok_or_else(|| {
                        invalid(
                            &part,
                            format!("sparse index {k} lies outside its buffer view"),
                        )
                    })?;
                if u64::from(target) >= count {
                    return Err(invalid(
                        part,
                        format!("sparse index {k} is {target}, out of range (count {count})"),
                    ));
                }
                for c in 0..multiplicity {
                    let value_at = (k * multiplicity as u64 + c as u64)
                        .checked_mul(component_size as u64)
                        .and_then(|x| x.checked_add(sparse.values.byte_offset.0));
                    let value = value_at
                        .and_then(|at| slice_at(value_bytes, at, component_size as u64))
                        .map(|b| decode(component, accessor.normalized, b))
                        .ok_or_else(|| {
                            invalid(
                                &part,
                                format!("sparse value {k} lies outside its buffer view"),
                            )
                        })?;
                    if let Some(slot) = values.get_mut(target as usize * multiplicity + c) {
                        *slot = value;
                    }
                }
            }
        }
        Ok(values)
    }

    /// The bytes of a buffer view and its stride; `context` names who refers to it.
    pub(super) fn view_bytes(
        &self,
        index: usize,
        context: &str,
    ) -> Result<(&[u8], Option<usize>), LoadError> {
        let Some(view) = self.root.buffer_views.get(index) else {
            return Err(invalid(
                context,
                format!("buffer view {index} does not exist"),
            ));
        };
        let part = format!(
            "{context}: {}",
            named("buffer view", index, view.name.as_deref())
        );
        let buffer_index = view.buffer.value();
        let Some(buffer) = self.buffers.get(buffer_index) else {
            return Err(invalid(
                part,
                format!("buffer {buffer_index} does not exist"),
            ));
        };
        let offset = view.byte_offset.map_or(0, |o| o.0);
        let length = view.byte_length.0;
        let bytes = slice_at(buffer, offset, length).ok_or_else(|| {
            invalid(
                &part,
                format!(
                    "bytes {offset}..{} lie outside buffer {buffer_index} ({} bytes)",
                    offset.saturating_add(length),
                    buffer.len()
                ),
            )
        })?;
        Ok((bytes, view.byte_stride.map(|s| s.0)))
    }
}
