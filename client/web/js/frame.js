// Decoder of the binary frame message (protocol/src/frame.rs is the reference):
// a 68-byte little-endian header, 8 bytes per stage, the progressive method's sample count and
// relative error (8 bytes, absent from older servers), then the payload: a JPEG or PNG image,
// or one H.264 access unit (Annex B).

const FIXED_LEN = 68;
const STAGE_LEN = 8;
const PROGRESS_LEN = 8;
const MAGIC = 0x5246434c; // "LCFR" read as a little-endian u32
const SUPPORTED_VERSION = 1;

export const FLAG_STILL = 1;
export const FLAG_GI_PENDING = 2;
export const FLAG_MOVING = 4;
export const FLAG_KEYFRAME = 8;

/** The codec byte's names (protocol `Codec::wire`). */
const CODECS = ['jpeg', 'png', 'h264'];
const MIMES = { jpeg: 'image/jpeg', png: 'image/png' };

export class FrameError extends Error {}

/** Splits a binary WebSocket message into its header and image payload. */
export function decodeFrame(buffer) {
  if (buffer.byteLength < FIXED_LEN) {
    throw new FrameError(`frame of ${buffer.byteLength} bytes is shorter than its header`);
  }
  const v = new DataView(buffer);
  if (v.getUint32(0, true) !== MAGIC) throw new FrameError('frame does not start with LCFR');
  const version = v.getUint16(4, true);
  if (version > SUPPORTED_VERSION) {
    throw new FrameError(`frame format version ${version} is newer than this viewer (${SUPPORTED_VERSION}); reload the page`);
  }
  const headerLen = v.getUint16(6, true);
  const stageCount = v.getUint8(50);
  if (headerLen < FIXED_LEN + STAGE_LEN * stageCount || headerLen > buffer.byteLength) {
    throw new FrameError(`header length ${headerLen} does not fit ${stageCount} stages`);
  }
  const payloadLen = v.getUint32(64, true);
  if (headerLen + payloadLen !== buffer.byteLength) {
    throw new FrameError(`payload of ${buffer.byteLength - headerLen} bytes, header says ${payloadLen}`);
  }
  const codec = CODECS[v.getUint8(48)];
  if (!codec) throw new FrameError(`unknown codec ${v.getUint8(48)}`);
  const stages = [];
  for (let i = 0; i < stageCount; i++) {
    const o = FIXED_LEN + STAGE_LEN * i;
    // Flags bit 0: the stage's output was reused from an earlier frame (0 ms, no GPU work);
    // bits 8–15: the sessions whose frames its output serves (0: this frame alone).
    const flags = v.getUint16(o + 2, true);
    stages.push({ index: v.getUint16(o, true), ms: v.getFloat32(o + 4, true), reused: (flags & 1) !== 0, sharedBy: flags >> 8 });
  }
  const progress = FIXED_LEN + STAGE_LEN * stageCount;
  const hasProgress = headerLen >= progress + PROGRESS_LEN;
  return {
    seq: Number(v.getBigUint64(8, true)),
    inputId: Number(v.getBigUint64(16, true)),
    renderStartUs: Number(v.getBigUint64(24, true)),
    sendUs: Number(v.getBigUint64(32, true)),
    width: v.getUint32(40, true),
    height: v.getUint32(44, true),
    codec,
    /** The image type of a JPEG or PNG payload; `null` for video. */
    mime: MIMES[codec] || null,
    flags: v.getUint8(49),
    quality: v.getUint8(51),
    encodeMs: v.getFloat32(52, true),
    readbackMs: v.getFloat32(56, true),
    gpuMs: v.getFloat32(60, true),
    stages,
    samples: hasProgress ? v.getUint32(progress, true) : 0,
    relativeError: hasProgress ? v.getFloat32(progress + 4, true) : 0,
    payload: new Uint8Array(buffer, headerLen, payloadLen),
    bytes: buffer.byteLength,
  };
}
