// A lossless still of the current view: a one-shot `POST /v1/render` as PNG, saved with its
// timing report (build, adapter, request hash, per-stage GPU ms) inside the PNG as an iTXt
// chunk with the keyword `lightcast-report`, so the numbers travel with the picture.

import { request } from './api.js';

const REPORT_KEYWORD = 'lightcast-report';

let crcTable = null;

function crc32(bytes) {
  if (!crcTable) {
    crcTable = new Uint32Array(256);
    for (let n = 0; n < 256; n++) {
      let c = n;
      for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
      crcTable[n] = c >>> 0;
    }
  }
  let c = 0xffffffff;
  for (const b of bytes) c = crcTable[(c ^ b) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

/** `png` with an iTXt chunk (uncompressed UTF-8 `text` under `keyword`) before its IEND. */
export function withTextChunk(png, keyword, text) {
  const enc = new TextEncoder();
  const data = [...enc.encode(keyword), 0, 0, 0, 0, 0, ...enc.encode(text)];
  const chunk = new Uint8Array(12 + data.length);
  const view = new DataView(chunk.buffer);
  view.setUint32(0, data.length);
  chunk.set(enc.encode('iTXt'), 4);
  chunk.set(data, 8);
  view.setUint32(8 + data.length, crc32(chunk.subarray(4, 8 + data.length)));
  const iendAt = png.length - 12;
  const out = new Uint8Array(png.length + chunk.length);
  out.set(png.subarray(0, iendAt), 0);
  out.set(chunk, iendAt);
  out.set(png.subarray(iendAt), iendAt + chunk.length);
  return out;
}

/** Renders `render` (RenderParams) as PNG; returns the file's bytes and the report. */
export async function renderStill(render) {
  const response = await request('POST', 'v1/render', { json: { render, format: 'png' } });
  const report = JSON.parse(response.headers.get('x-lightcast-report') || '{}');
  const png = new Uint8Array(await response.arrayBuffer());
  return { png: withTextChunk(png, REPORT_KEYWORD, JSON.stringify(report)), report };
}

/** Hands `bytes` to the browser as a download named `name`. */
export function download(bytes, name, type) {
  const href = URL.createObjectURL(new Blob([bytes], { type }));
  const a = document.createElement('a');
  a.href = href;
  a.download = name;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(href), 60000);
}
