//! Copies a texture into a mappable buffer and hands back tightly packed rows.
//!
//! wgpu requires `bytes_per_row` of texture→buffer copies to be a multiple of 256, so rows are
//! padded on the GPU side and the padding is stripped while reading.

use super::{GpuContext, GpuError};

/// Bytes per row of a copy of `width` pixels of `bytes_per_pixel`, rounded up to wgpu's alignment.
pub fn padded_bytes_per_row(width: u32, bytes_per_pixel: u32) -> u32 {
    let unpadded = width * bytes_per_pixel;
    unpadded.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

/// Removes the per-row padding of a copied image.
pub fn strip_row_padding(padded: &[u8], width: u32, height: u32, bytes_per_pixel: u32) -> Vec<u8> {
    let row = (width * bytes_per_pixel) as usize;
    let stride = padded_bytes_per_row(width, bytes_per_pixel) as usize;
    let mut out = Vec::with_capacity(row * height as usize);
    for y in 0..height as usize {
        out.extend_from_slice(&padded[y * stride..y * stride + row]);
    }
    out
}

/// A staging buffer sized for one texture.
#[derive(Clone)]
pub struct TextureReadback {
    buffer: wgpu::Buffer,
    width: u32,
    height: u32,
    bytes_per_pixel: u32,
}

impl TextureReadback {
    pub fn new(
        device: &wgpu::Device,
        label: &str,
        width: u32,
        height: u32,
        bytes_per_pixel: u32,
    ) -> Self {
        let size = u64::from(padded_bytes_per_row(width, bytes_per_pixel)) * u64::from(height);
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        Self {
            buffer,
            width,
            height,
            bytes_per_pixel,
        }
    }

    pub fn encode_copy(&self, encoder: &mut wgpu::CommandEncoder, texture: &wgpu::Texture) {
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &self.buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded_bytes_per_row(self.width, self.bytes_per_pixel)),
                    rows_per_image: Some(self.height),
                },
            },
            wgpu::Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
        );
    }

    /// Starts mapping the buffer; [`PendingRows::finish`] returns packed rows once the copy
    /// has finished (after the caller polled the device).
    pub fn begin_read(&self) -> PendingRows {
        PendingRows {
            map: PendingMap::new(&self.buffer),
            width: self.width,
            height: self.height,
            bytes_per_pixel: self.bytes_per_pixel,
        }
    }

    /// Maps the buffer (blocking until all submitted work has finished) and returns packed rows.
    pub fn read(&self, ctx: &GpuContext) -> Result<Vec<u8>, GpuError> {
        let pending = self.begin_read();
        ctx.wait_idle()?;
        pending.finish()
    }
}

/// A texture copy being mapped.
pub struct PendingRows {
    map: PendingMap,
    width: u32,
    height: u32,
    bytes_per_pixel: u32,
}

impl PendingRows {
    pub fn finish(self) -> Result<Vec<u8>, GpuError> {
        let bytes = self.map.finish()?;
        Ok(strip_row_padding(
            &bytes,
            self.width,
            self.height,
            self.bytes_per_pixel,
        ))
    }
}

/// A whole `MAP_READ` buffer being mapped. Mapping completes once the GPU work that writes the
/// buffer is done and the device was polled; [`PendingMap::finish`] then copies the contents
/// out and unmaps.
pub struct PendingMap {
    buffer: wgpu::Buffer,
    done: std::sync::mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>,
}

impl PendingMap {
    pub fn new(buffer: &wgpu::Buffer) -> Self {
        let (tx, done) = std::sync::mpsc::channel();
        buffer.map_async(wgpu::MapMode::Read, .., move |r| {
            // The receiver only disappears if the frame was abandoned.
            let _ = tx.send(r);
        });
        Self {
            buffer: buffer.clone(),
            done,
        }
    }

    /// The contents; the device must have been polled past the writing submission.
    pub fn finish(self) -> Result<Vec<u8>, GpuError> {
        self.done
            .recv()
            .map_err(|e| GpuError::Map(e.to_string()))?
            .map_err(|e| GpuError::Map(e.to_string()))?;
        let bytes = self
            .buffer
            .get_mapped_range(..)
            .map_err(|e| GpuError::Map(e.to_string()))?
            .to_vec();
        self.buffer.unmap();
        Ok(bytes)
    }
}

/// Encodes a copy of a whole `COPY_SRC` buffer into a new `MAP_READ` buffer, returned for
/// reading once the encoder's submission has finished.
pub fn stage_buffer(
    device: &wgpu::Device,
    encoder: &mut wgpu::CommandEncoder,
    buffer: &wgpu::Buffer,
) -> wgpu::Buffer {
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: buffer.size(),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, None);
    staging
}

/// Copies a whole `COPY_SRC` buffer into a new staging buffer and reads it (blocking: for
/// tests and debugging, not the frame loop).
pub fn read_buffer(ctx: &GpuContext, buffer: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: buffer.size(),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, None);
    ctx.queue.submit([encoder.finish()]);
    map_read(ctx, &staging)
}

/// Blocking map of a whole `MAP_READ` buffer (waits for all submitted work); copies the
/// contents out and unmaps.
pub fn map_read(ctx: &GpuContext, buffer: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
    let pending = PendingMap::new(buffer);
    ctx.wait_idle()?;
    pending.finish()
}

/// RGBA texels read back as f32: 16 bytes per texel (`Rgba32Float`) as they are, 8
/// (`Rgba16Float`) widened from f16.
pub fn rgba_f32(bytes: &[u8], bytes_per_texel: u32) -> Vec<[f32; 4]> {
    if bytes_per_texel == 8 {
        bytemuck::pod_collect_to_vec::<u8, half::f16>(bytes)
            .chunks_exact(4)
            .map(|c| [c[0].to_f32(), c[1].to_f32(), c[2].to_f32(), c[3].to_f32()])
            .collect()
    } else {
        bytemuck::pod_collect_to_vec(bytes)
    }
}

/// Copies a whole RGBA float texture (`Rgba32Float` or `Rgba16Float`, `COPY_SRC`) and reads
/// it as f32 (blocking: for tests and debugging, not the frame loop).
pub fn read_rgba_texture(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
) -> Result<Vec<[f32; 4]>, GpuError> {
    let bytes_per_texel = match texture.format() {
        wgpu::TextureFormat::Rgba16Float => 8,
        _ => 16,
    };
    Ok(rgba_f32(
        &read_texture_bytes(ctx, texture, bytes_per_texel)?,
        bytes_per_texel,
    ))
}

/// An `Rgba32Uint` texture's texels (blocking; for tests and debug views).
pub fn read_rgba_u32_texture(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
) -> Result<Vec<[u32; 4]>, GpuError> {
    Ok(bytemuck::pod_collect_to_vec(&read_texture_bytes(
        ctx, texture, 16,
    )?))
}

fn read_texture_bytes(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    bytes_per_texel: u32,
) -> Result<Vec<u8>, GpuError> {
    let size = texture.size();
    let readback = TextureReadback::new(
        &ctx.device,
        "rgba readback",
        size.width,
        size.height,
        bytes_per_texel,
    );
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    readback.encode_copy(&mut encoder, texture);
    ctx.queue.submit([encoder.finish()]);
    readback.read(ctx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_padded_to_256_bytes() {
        assert_eq!(padded_bytes_per_row(64, 4), 256);
        assert_eq!(padded_bytes_per_row(65, 4), 512);
        assert_eq!(padded_bytes_per_row(1, 8), 256);
        assert_eq!(padded_bytes_per_row(1920, 4), 7680);
    }

    #[test]
    fn padding_is_stripped_row_by_row() {
        let (w, h, bpp) = (3u32, 2u32, 4u32);
        let stride = padded_bytes_per_row(w, bpp) as usize;
        let mut padded = vec![0xEEu8; stride * h as usize];
        for y in 0..h as usize {
            for i in 0..(w * bpp) as usize {
                padded[y * stride + i] = (y * 100 + i) as u8;
            }
        }
        let packed = strip_row_padding(&padded, w, h, bpp);
        assert_eq!(packed.len(), 24);
        assert_eq!(packed[0], 0);
        assert_eq!(packed[11], 11);
        assert_eq!(packed[12], 100);
        assert!(!packed.contains(&0xEE));
    }
}
