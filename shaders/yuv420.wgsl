// The tone-mapped frame as Y'CbCr 4:2:0 (BT.709 matrix, limited range) for the video encoder:
// three planes, each row padded to a multiple of 4 bytes, packed four samples to a u32 (WGSL
// has no byte stores). Each invocation writes one u32 of each chroma plane: four chroma
// samples of one chroma row, i.e. the 8×2 luma block under them (four luma u32s).
// `server/passes/src/passes/yuv420.rs` has the CPU port and the layout.

struct YuvParams {
    width: u32,
    height: u32,
    // Bytes per row of the luma plane (twice the chroma stride, a multiple of 8).
    luma_stride: u32,
    // Bytes per row of each chroma plane (a multiple of 4).
    chroma_stride: u32,
    // Byte offsets of the Cb and Cr planes (the luma plane starts at 0).
    cb_offset: u32,
    cr_offset: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<storage, read> params: YuvParams;
@group(0) @binding(1) var ldr: texture_2d<f32>;
@group(0) @binding(2) var<storage, read_write> planes: array<u32>;

// BT.709 luma weights (Rec. ITU-R BT.709-6, item 3.2); limited range: Y' in 16..235, Cb and Cr
// in 16..240 (item 3.4 quantisation, 8 bits).
const KR: f32 = 0.2126;
const KB: f32 = 0.0722;

fn luma(c: vec3<f32>) -> f32 {
    return KR * c.r + (1.0 - KR - KB) * c.g + KB * c.b;
}

// The sRGB-encoded colour of a pixel, clamped to the image (rows and columns past the edge of
// an odd size repeat the last one).
fn pixel(x: u32, y: u32) -> vec3<f32> {
    let p = vec2<i32>(vec2<u32>(min(x, params.width - 1u), min(y, params.height - 1u)));
    return textureLoad(ldr, p, 0).rgb;
}

fn quantise(v: f32) -> u32 {
    return u32(clamp(floor(v + 0.5), 0.0, 255.0));
}

fn luma_byte(c: vec3<f32>) -> u32 {
    return quantise(16.0 + 219.0 * luma(c));
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let chroma_words = params.chroma_stride / 4u;
    let chroma_rows = (params.height + 1u) / 2u;
    if id.x >= chroma_words || id.y >= chroma_rows {
        return;
    }
    var cb_word = 0u;
    var cr_word = 0u;
    var luma_words = array<u32, 4>(0u, 0u, 0u, 0u);
    for (var i = 0u; i < 4u; i++) {
        let x = 8u * id.x + 2u * i;
        let y = 2u * id.y;
        let c00 = pixel(x, y);
        let c10 = pixel(x + 1u, y);
        let c01 = pixel(x, y + 1u);
        let c11 = pixel(x + 1u, y + 1u);
        // Luma bytes 2i and 2i+1 of rows y and y+1: word i/2 of the 8-pixel run, byte 2(i%2).
        let shift = 16u * (i % 2u);
        let top = luma_byte(c00) | (luma_byte(c10) << 8u);
        let bottom = luma_byte(c01) | (luma_byte(c11) << 8u);
        luma_words[i / 2u] |= top << shift;
        luma_words[2u + i / 2u] |= bottom << shift;
        // Chroma of the block's mean colour (sited between the four luma samples).
        let mean = 0.25 * (c00 + c10 + c01 + c11);
        let y_mean = luma(mean);
        let cb = quantise(128.0 + 224.0 * (mean.b - y_mean) / (2.0 * (1.0 - KB)));
        let cr = quantise(128.0 + 224.0 * (mean.r - y_mean) / (2.0 * (1.0 - KR)));
        cb_word |= cb << (8u * i);
        cr_word |= cr << (8u * i);
    }
    let luma_row = 2u * id.y;
    let luma_word = (luma_row * params.luma_stride) / 4u + 2u * id.x;
    planes[luma_word] = luma_words[0];
    planes[luma_word + 1u] = luma_words[1];
    // An odd height has no second row in the plane.
    if luma_row + 1u < params.height {
        let next = luma_word + params.luma_stride / 4u;
        planes[next] = luma_words[2];
        planes[next + 1u] = luma_words[3];
    }
    let chroma_word = id.y * chroma_words + id.x;
    planes[params.cb_offset / 4u + chroma_word] = cb_word;
    planes[params.cr_offset / 4u + chroma_word] = cr_word;
}
