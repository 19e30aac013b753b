// H.264 frames (codec byte 2) decoded with WebCodecs' VideoDecoder. The server sends one
// Annex B access unit per frame message, SPS and PPS in front of every keyframe, so the
// decoder is configured without a `description` (WebCodecs then reads Annex B) from the
// keyframe's own SPS, and configured again when a keyframe brings a different one (a resize,
// or interactive_scale switching between the moving and the full size).

import { FLAG_KEYFRAME } from './frame.js';

// Probed once at start: constrained baseline, level 5.1 (the server encodes up to 3840×2160).
const PROBE_CODEC = 'avc1.42E033';

/**
 * Whether this page can decode the server's H.264. WebCodecs exists only in secure contexts
 * (https, or http on localhost), and some browsers ship it without H.264.
 */
export async function canDecodeH264() {
  if (typeof VideoDecoder === 'undefined' || typeof EncodedVideoChunk === 'undefined') return false;
  try {
    const { supported } = await VideoDecoder.isConfigSupported({ codec: PROBE_CODEC, optimizeForLatency: true });
    return supported === true;
  } catch {
    return false;
  }
}

/**
 * The RFC 6381 codec string (`avc1.PPCCLL`) of the first SPS in an Annex B access unit:
 * profile_idc, the constraint flags and level_idc are the three bytes after the SPS's NAL
 * header. `null` when the unit has no SPS.
 */
export function codecString(unit) {
  for (let i = 0; i + 4 < unit.length; i++) {
    // A start code (00 00 01; the four-byte form ends the same way) then the NAL header.
    if (unit[i] !== 0 || unit[i + 1] !== 0 || unit[i + 2] !== 1) continue;
    if ((unit[i + 3] & 0x1f) !== 7) continue;
    if (i + 6 >= unit.length) return null;
    const hex = (b) => b.toString(16).padStart(2, '0').toUpperCase();
    return `avc1.${hex(unit[i + 4])}${hex(unit[i + 5])}${hex(unit[i + 6])}`;
  }
  return null;
}

/**
 * One session's H.264 decoder. `onPicture(videoFrame, frame, decodeMs)` gets each decoded
 * picture with the header of the message it came from and the time it took to decode (the
 * callee closes the picture); `onNeedKeyframe(reason)` when the stream cannot go on until a
 * keyframe arrives (it asks the server for one).
 */
export class H264Decoder {
  constructor(onPicture, onNeedKeyframe) {
    this.onPicture = onPicture;
    this.onNeedKeyframe = onNeedKeyframe;
    this.decoder = null;
    this.codec = null;
    this.size = null;
    /** Frames handed to the decoder and not yet out, by sequence number (the chunk timestamp). */
    this.pending = new Map();
    this.waitingForKeyframe = true;
    this.askedAt = -Infinity;
  }

  /** Decodes one codec-2 frame (see `decodeFrame`). */
  decode(frame) {
    const keyframe = (frame.flags & FLAG_KEYFRAME) !== 0;
    if (keyframe) {
      const codec = codecString(frame.payload);
      if (!codec) {
        this.fail('a keyframe without an SPS');
        return;
      }
      if (!this.decoder || this.decoder.state === 'closed') this.create();
      const size = `${frame.width}x${frame.height}`;
      if (codec !== this.codec || size !== this.size) {
        this.decoder.configure({ codec, optimizeForLatency: true, codedWidth: frame.width, codedHeight: frame.height });
        this.codec = codec;
        this.size = size;
      }
      this.waitingForKeyframe = false;
    }
    if (this.waitingForKeyframe) {
      // Delta frames before the first keyframe (a reload mid-stream) cannot be decoded.
      this.askForKeyframe('waiting for a keyframe');
      return;
    }
    this.pending.set(frame.seq, { frame, started: performance.now() });
    try {
      this.decoder.decode(new EncodedVideoChunk({ type: keyframe ? 'key' : 'delta', timestamp: frame.seq, data: frame.payload }));
    } catch (e) {
      this.fail(e.message);
    }
  }

  create() {
    this.decoder = new VideoDecoder({
      output: (picture) => {
        const entry = this.pending.get(picture.timestamp);
        this.pending.delete(picture.timestamp);
        if (!entry) {
          picture.close();
          return;
        }
        // Pictures come out in decode order: anything older that never came out was lost.
        for (const seq of this.pending.keys()) if (seq < picture.timestamp) this.pending.delete(seq);
        this.onPicture(picture, entry.frame, performance.now() - entry.started);
      },
      error: (e) => this.fail(e.message),
    });
    this.codec = null;
    this.size = null;
  }

  /** The decoder failed (it closes itself): start again at the next keyframe. */
  fail(reason) {
    if (this.decoder && this.decoder.state !== 'closed') this.decoder.close();
    this.decoder = null;
    this.pending.clear();
    this.waitingForKeyframe = true;
    this.askForKeyframe(`H.264 decoding failed: ${reason}`);
  }

  askForKeyframe(reason) {
    // One request per half second: the keyframe is on its way behind the frames in flight.
    const now = performance.now();
    if (now - this.askedAt < 500) return;
    this.askedAt = now;
    this.onNeedKeyframe(reason);
  }

  /** A new session numbers its frames from 1 again and starts with a keyframe. */
  reset() {
    if (this.decoder && this.decoder.state !== 'closed') this.decoder.close();
    this.decoder = null;
    this.pending.clear();
    this.waitingForKeyframe = true;
    this.askedAt = -Infinity;
  }
}
