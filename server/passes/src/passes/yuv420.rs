//! The tone-mapped frame as Y'CbCr 4:2:0 (`shaders/yuv420.wgsl`) for the video encoder: the
//! conversion runs on the GPU so a video frame reads back 1.5 bytes per pixel instead of 4 and
//! the CPU only entropy-codes it. BT.709 matrix, limited range (Y' 16–235, Cb/Cr 16–240),
//! applied to the sRGB-encoded values the tone map wrote; chroma is the 2×2 block's mean.
//! [`Yuv420::from_rgba8`] is the CPU port the tests compare with, and converts debug views
//! (composed on the CPU) for video too.

use super::bind::{self, bind_group};
use super::Target;
use crate::gpu::shaders;
use bytemuck::{Pod, Zeroable};

/// BT.709's luma weights of R and B (G takes the rest).
const KR: f32 = 0.2126;
const KB: f32 = 0.0722;

/// Where the three planes of a `width`×`height` frame lie in one buffer. Rows are padded to 4
/// bytes (chroma) and 8 bytes (luma, twice the chroma stride) so the GPU writes whole words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Yuv420Layout {
    pub width: u32,
    pub height: u32,
    pub luma_stride: u32,
    pub chroma_stride: u32,
}

impl Yuv420Layout {
    pub fn new(width: u32, height: u32) -> Self {
        let chroma_stride = width.div_ceil(2).next_multiple_of(4);
        Self {
            width,
            height,
            luma_stride: 2 * chroma_stride,
            chroma_stride,
        }
    }

    pub fn chroma_rows(&self) -> u32 {
        self.height.div_ceil(2)
    }

    pub fn cb_offset(&self) -> usize {
        (self.luma_stride * self.height) as usize
    }

    pub fn cr_offset(&self) -> usize {
        self.cb_offset() + (self.chroma_stride * self.chroma_rows()) as usize
    }

    /// Bytes of all three planes.
    pub fn bytes(&self) -> usize {
        self.cr_offset() + (self.chroma_stride * self.chroma_rows()) as usize
    }

    fn params(&self) -> YuvParams {
        YuvParams {
            width: self.width,
            height: self.height,
            luma_stride: self.luma_stride,
            chroma_stride: self.chroma_stride,
            cb_offset: self.cb_offset() as u32,
            cr_offset: self.cr_offset() as u32,
            pad0: 0,
            pad1: 0,
        }
    }
}

/// A frame in Y'CbCr 4:2:0, planes laid out as [`Yuv420Layout`] says.
#[derive(Clone, Debug, PartialEq)]
pub struct Yuv420 {
    pub layout: Yuv420Layout,
    pub data: Vec<u8>,
}

impl Yuv420 {
    pub fn y(&self) -> &[u8] {
        &self.data[..self.layout.cb_offset()]
    }

    pub fn cb(&self) -> &[u8] {
        &self.data[self.layout.cb_offset()..self.layout.cr_offset()]
    }

    pub fn cr(&self) -> &[u8] {
        &self.data[self.layout.cr_offset()..]
    }

    /// CPU port of `shaders/yuv420.wgsl` for a tightly packed RGBA8 image (sRGB-encoded).
    pub fn from_rgba8(rgba8: &[u8], width: u32, height: u32) -> Self {
        let layout = Yuv420Layout::new(width, height);
        let mut data = vec![0u8; layout.bytes()];
        let pixel = |x: u32, y: u32| -> [f32; 3] {
            let i = 4 * (y.min(height - 1) * width + x.min(width - 1)) as usize;
            [0, 1, 2].map(|c| f32::from(rgba8[i + c]) / 255.0)
        };
        let luma = |c: [f32; 3]| KR * c[0] + (1.0 - KR - KB) * c[1] + KB * c[2];
        let quantise = |v: f32| (v + 0.5).floor().clamp(0.0, 255.0) as u8;
        for y in 0..height {
            for x in 0..width {
                data[(y * layout.luma_stride + x) as usize] =
                    quantise(16.0 + 219.0 * luma(pixel(x, y)));
            }
        }
        for cy in 0..layout.chroma_rows() {
            for cx in 0..width.div_ceil(2) {
                let (x, y) = (2 * cx, 2 * cy);
                let block = [
                    pixel(x, y),
                    pixel(x + 1, y),
                    pixel(x, y + 1),
                    pixel(x + 1, y + 1),
                ];
                let mean = [0, 1, 2].map(|c| 0.25 * block.iter().map(|p| p[c]).sum::<f32>());
                let y_mean = luma(mean);
                let at = (cy * layout.chroma_stride + cx) as usize;
                data[layout.cb_offset() + at] =
                    quantise(128.0 + 224.0 * (mean[2] - y_mean) / (2.0 * (1.0 - KB)));
                data[layout.cr_offset() + at] =
                    quantise(128.0 + 224.0 * (mean[0] - y_mean) / (2.0 * (1.0 - KR)));
            }
        }
        Self { layout, data }
    }

    /// Back to RGBA8 (nearest chroma sample): what a decoder shows, for quality metrics.
    pub fn to_rgba8(&self) -> Vec<u8> {
        let l = self.layout;
        let mut out = Vec::with_capacity((l.width * l.height * 4) as usize);
        for y in 0..l.height {
            for x in 0..l.width {
                let luma = (f32::from(self.y()[(y * l.luma_stride + x) as usize]) - 16.0) / 219.0;
                let at = ((y / 2) * l.chroma_stride + x / 2) as usize;
                let cb = (f32::from(self.cb()[at]) - 128.0) / 224.0;
                let cr = (f32::from(self.cr()[at]) - 128.0) / 224.0;
                let r = luma + 2.0 * (1.0 - KR) * cr;
                let b = luma + 2.0 * (1.0 - KB) * cb;
                let g = (luma - KR * r - KB * b) / (1.0 - KR - KB);
                out.extend([r, g, b].map(|c| (c * 255.0).round().clamp(0.0, 255.0) as u8));
                out.push(255);
            }
        }
        out
    }
}

/// Mirrors `YuvParams` in `shaders/yuv420.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct YuvParams {
    pub width: u32,
    pub height: u32,
    pub luma_stride: u32,
    pub chroma_stride: u32,
    pub cb_offset: u32,
    pub cr_offset: u32,
    pub pad0: u32,
    pub pad1: u32,
}

bind_group! {
    /// Group 0 of `shaders/yuv420.wgsl`.
    pub struct Resources as GROUP("yuv420", wgpu::ShaderStages::COMPUTE) {
        params: bind::PARAMS,
        ldr: bind::TEXTURE,
        planes: bind::STORAGE_RW,
    }
}

/// The planes of one output size and the bind group that fills them from its LDR target.
pub struct Yuv420Target {
    pub layout: Yuv420Layout,
    /// The three planes (`COPY_SRC`, for the readback).
    pub planes: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

pub struct Yuv420Pass {
    pipeline: wgpu::ComputePipeline,
    group: wgpu::BindGroupLayout,
}

impl Yuv420Pass {
    pub fn new(device: &wgpu::Device) -> Self {
        let group = GROUP.layout(device);
        let module = shaders::YUV420.create_module(device);
        let pipeline = super::compute_pipeline(device, "yuv420", &group, &module, "main");
        Self { pipeline, group }
    }

    /// Planes for the `width`×`height` image in `ldr` (a `TEXTURE_BINDING` of the LDR format).
    pub fn target(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        ldr: &Target,
        width: u32,
        height: u32,
    ) -> Yuv420Target {
        let layout = Yuv420Layout::new(width, height);
        let params =
            super::params_buffer(device, "yuv420 params", std::mem::size_of::<YuvParams>());
        queue.write_buffer(&params, 0, bytemuck::bytes_of(&layout.params()));
        let planes = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("yuv420 planes"),
            size: layout.bytes() as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let bind_group = Resources {
            params: &params,
            ldr,
            planes: &planes,
        }
        .bind(device, &self.group);
        Yuv420Target {
            layout,
            planes,
            bind_group,
        }
    }

    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, target: &Yuv420Target) {
        let mut pass = super::begin_compute(encoder, "yuv420");
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &target.bind_group, &[]);
        let words = target.layout.chroma_stride / 4;
        pass.dispatch_workgroups(
            words.div_ceil(super::TILE),
            target.layout.chroma_rows().div_ceil(super::TILE),
            1,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shaders::{layout_check::assert_struct, YUV420};
    use std::mem::{offset_of, size_of};

    #[test]
    fn params_match_wgsl() {
        assert_struct(
            &YUV420,
            "YuvParams",
            size_of::<YuvParams>(),
            &[
                ("width", offset_of!(YuvParams, width)),
                ("height", offset_of!(YuvParams, height)),
                ("luma_stride", offset_of!(YuvParams, luma_stride)),
                ("chroma_stride", offset_of!(YuvParams, chroma_stride)),
                ("cb_offset", offset_of!(YuvParams, cb_offset)),
                ("cr_offset", offset_of!(YuvParams, cr_offset)),
                ("pad0", offset_of!(YuvParams, pad0)),
                ("pad1", offset_of!(YuvParams, pad1)),
            ],
        );
    }

    #[test]
    fn layout_pads_rows_to_whole_words() {
        let l = Yuv420Layout::new(1920, 1080);
        assert_eq!((l.luma_stride, l.chroma_stride), (1920, 960));
        assert_eq!(l.bytes(), 1920 * 1080 * 3 / 2);
        let odd = Yuv420Layout::new(66, 37);
        assert_eq!(
            (odd.luma_stride, odd.chroma_stride, odd.chroma_rows()),
            (72, 36, 19)
        );
        assert_eq!(odd.bytes(), 72 * 37 + 2 * 36 * 19);
    }

    #[test]
    fn primaries_and_greys_land_on_bt709_limited_range_codes() {
        let cases: [([u8; 3], [u8; 3]); 5] = [
            ([0, 0, 0], [16, 128, 128]),
            ([255, 255, 255], [235, 128, 128]),
            // BT.709 limited-range codes of the primaries (Rec. BT.709 colour bars).
            ([255, 0, 0], [63, 102, 240]),
            ([0, 255, 0], [173, 42, 26]),
            ([0, 0, 255], [32, 240, 118]),
        ];
        for (rgb, ycbcr) in cases {
            let rgba: Vec<u8> = (0..4).flat_map(|_| [rgb[0], rgb[1], rgb[2], 255]).collect();
            let yuv = Yuv420::from_rgba8(&rgba, 2, 2);
            assert_eq!([yuv.y()[0], yuv.cb()[0], yuv.cr()[0]], ycbcr, "{rgb:?}");
            let back = yuv.to_rgba8();
            for c in 0..3 {
                assert!(back[c].abs_diff(rgb[c]) <= 2, "{rgb:?} -> {back:?}");
            }
        }
    }

    #[test]
    fn chroma_is_the_mean_of_each_two_by_two_block() {
        // Left block black, right block white; odd width: the last column repeats.
        let (w, h) = (5u32, 2u32);
        let rgba: Vec<u8> = (0..w * h)
            .flat_map(|i| {
                if i % w < 2 {
                    [0, 0, 0, 255]
                } else {
                    [200, 40, 40, 255]
                }
            })
            .collect();
        let yuv = Yuv420::from_rgba8(&rgba, w, h);
        assert_eq!(yuv.cb()[0], 128);
        assert_eq!(
            yuv.cb()[1],
            yuv.cb()[2],
            "the last block repeats its column"
        );
        assert!(yuv.cr()[1] > 128, "reddish");
        assert_eq!(yuv.y()[4], yuv.y()[3]);
    }
}
