//! Materials and their base-colour textures: glTF's metallic-roughness parameters, emission,
//! and images decoded, downscaled and counted against the texture budget.

use super::*;

impl Loader<'_> {
    pub(super) fn material_index(&mut self, material: Option<usize>) -> Result<u32, LoadError> {
        let Some(index) = material else {
            if let Some(default) = self.default_material {
                return Ok(default);
            }
            let default = self.materials.len() as u32;
            self.materials.push(Material::default());
            self.default_material = Some(default);
            return Ok(default);
        };
        if let Some(&Some(mapped)) = self.material_map.get(index) {
            return Ok(mapped);
        }
        let converted = self.convert_material(index)?;
        let mapped = self.materials.len() as u32;
        self.materials.push(converted);
        if let Some(slot) = self.material_map.get_mut(index) {
            *slot = Some(mapped);
        }
        Ok(mapped)
    }

    pub(super) fn convert_material(&mut self, index: usize) -> Result<Material, LoadError> {
        let Some(material) = self.root.materials.get(index) else {
            return Err(invalid(format!("material {index}"), "does not exist"));
        };
        let part = named("material", index, material.name.as_deref());
        let pbr = &material.pbr_metallic_roughness;
        let strength = material
            .extensions
            .as_ref()
            .and_then(|e| e.emissive_strength.as_ref())
            .map_or(1.0, |s| s.emissive_strength.0);
        let emissive = material.emissive_factor.0.map(|e| e * strength);
        let specular = material
            .extensions
            .as_ref()
            .and_then(|e| e.specular.as_ref());
        if specular.is_some_and(|s| {
            s.specular_texture.is_some()
                || s.specular_color_texture.is_some()
                || s.specular_color_factor.0 != [1.0; 3]
        }) {
            tracing::warn!(
                "{part}: KHR_materials_specular's textures and specularColorFactor are not \
                 supported; only specularFactor is used"
            );
        }
        let specular = specular.map_or(1.0, |s| s.specular_factor.0);
        if !(0.0..=1.0).contains(&specular) {
            tracing::warn!("{part}: specularFactor {specular} is clamped to [0, 1]");
        }
        let base_color = pbr.base_color_factor.0;
        let (metallic, roughness) = (pbr.metallic_factor.0, pbr.roughness_factor.0);
        let factors = base_color
            .iter()
            .chain(&emissive)
            .chain([&metallic, &roughness, &specular]);
        if !factors.into_iter().all(|f| f.is_finite()) {
            return Err(invalid(part, "has a non-finite factor"));
        }
        let alpha_cutoff = match material.alpha_mode {
            Checked::Valid(AlphaMode::Opaque) => None,
            Checked::Valid(AlphaMode::Mask) => {
                Some(material.alpha_cutoff.as_ref().map_or(0.5, |c| c.0))
            }
            Checked::Valid(AlphaMode::Blend) => {
                tracing::warn!("{part}: alphaMode BLEND is not supported; rendering it opaque");
                None
            }
            Checked::Invalid => return Err(invalid(part, "alphaMode is invalid")),
        };
        let base_color_texture = match &pbr.base_color_texture {
            Some(info) if info.tex_coord != 0 => {
                tracing::warn!(
                    "{part}: base colour texture uses TEXCOORD_{}; only TEXCOORD_0 is \
                     supported, so the texture is ignored",
                    info.tex_coord
                );
                None
            }
            Some(info) => Some(self.texture(info.index.value(), &part)?),
            None => None,
        };
        Ok(Material {
            name: material
                .name
                .clone()
                .unwrap_or_else(|| format!("material {index}")),
            base_color,
            metallic,
            roughness,
            specular,
            emissive,
            base_color_texture,
            alpha_cutoff,
        })
    }

    /// Index in `textures` of a glTF texture's image, decoding the image on first use.
    pub(super) fn texture(&mut self, index: usize, context: &str) -> Result<usize, LoadError> {
        let root = self.root;
        let Some(texture) = root.textures.get(index) else {
            return Err(invalid(context, format!("texture {index} does not exist")));
        };
        let image_index = texture.source.value();
        if let Some(&Some(mapped)) = self.image_map.get(image_index) {
            return Ok(mapped);
        }
        let texture_part = named("texture", index, texture.name.as_deref());
        let Some(image) = root.images.get(image_index) else {
            return Err(invalid(
                texture_part,
                format!("image {image_index} does not exist"),
            ));
        };
        let part = format!(
            "{texture_part} ({})",
            named("image", image_index, image.name.as_deref())
        );
        let bytes: Cow<[u8]> = match (&image.uri, image.buffer_view) {
            (Some(uri), _) => Cow::Owned(read_uri(uri, self.base_dir, &part)?),
            (None, Some(view)) => Cow::Borrowed(self.view_bytes(view.value(), &part)?.0),
            (None, None) => return Err(invalid(part, "has neither a uri nor a bufferView")),
        };
        let name = image
            .name
            .clone()
            .or_else(|| image.uri.clone().filter(|u| !u.starts_with("data:")))
            .unwrap_or_else(|| format!("image {image_index}"));
        let remaining = self.limits.max_texture_bytes - self.texture_bytes;
        let decoded = decode_image(&bytes, name, &part, remaining, self.limits.max_texture_size)?;
        self.texture_bytes += decoded.rgba8.len() as u64;
        let mapped = self.textures.len();
        self.textures.push(decoded);
        if let Some(slot) = self.image_map.get_mut(image_index) {
            *slot = Some(mapped);
        }
        Ok(mapped)
    }
}

/// The size an image of `width`×`height` is kept at: within `max_side` on both axes, the
/// aspect ratio kept (each side at least 1).
pub fn kept_size(width: u32, height: u32, max_side: u32) -> (u32, u32) {
    let longest = width.max(height);
    if longest <= max_side {
        return (width, height);
    }
    let scale = |side: u32| {
        let scaled = u64::from(side) * u64::from(max_side) / u64::from(longest);
        (scaled as u32).max(1)
    };
    (scale(width), scale(height))
}

/// Decodes a PNG or JPEG to RGBA8, keeping the sRGB-encoded bytes as they are, downscaled to
/// at most `max_side` texels a side, if its kept pixels fit in `max_bytes`.
pub(super) fn decode_image(
    bytes: &[u8],
    name: String,
    part: &str,
    max_bytes: u64,
    max_side: u32,
) -> Result<Texture, LoadError> {
    let decode_error = |error| LoadError::ImageDecode {
        part: part.to_owned(),
        error,
    };
    let format = image::guess_format(bytes).map_err(decode_error)?;
    if !matches!(format, image::ImageFormat::Png | image::ImageFormat::Jpeg) {
        return Err(invalid(
            part,
            format!("image format {format:?} is not supported (only PNG and JPEG)"),
        ));
    }
    // Dimensions come from the header alone, so oversized images are refused before the
    // pixel buffer is allocated.
    let (width, height) = image::ImageReader::with_format(io::Cursor::new(bytes), format)
        .into_dimensions()
        .map_err(decode_error)?;
    if width > MAX_TEXTURE_SIZE || height > MAX_TEXTURE_SIZE {
        return Err(invalid(
            part,
            format!(
                "image is {width}×{height} pixels; at most {MAX_TEXTURE_SIZE} in either \
                 dimension is supported"
            ),
        ));
    }
    let (kept_width, kept_height) = kept_size(width, height, max_side);
    let kept_bytes = 4 * u64::from(kept_width) * u64::from(kept_height);
    if kept_bytes > max_bytes {
        return Err(LoadError::TextureBudget {
            part: part.to_owned(),
            width,
            height,
            kept_width,
            kept_height,
            needed: kept_bytes,
            available: max_bytes,
        });
    }
    let mut rgba = image::load_from_memory_with_format(bytes, format)
        .map_err(decode_error)?
        .into_rgba8();
    if (kept_width, kept_height) != (width, height) {
        // Filtered in the sRGB encoding the bytes are in: a slight darkening of high-contrast
        // detail, invisible at the frame sizes that made the full size unnecessary.
        rgba = image::imageops::resize(
            &rgba,
            kept_width,
            kept_height,
            image::imageops::FilterType::Triangle,
        );
    }
    Ok(Texture {
        name,
        width: rgba.width(),
        height: rgba.height(),
        rgba8: rgba.into_raw(),
    })
}
