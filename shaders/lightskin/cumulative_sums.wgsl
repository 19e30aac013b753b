// Cumulative sums of the importance map: down every column, then across the column totals,
// so that VALs can be drawn by binary search (the paper's SAT step, eq. 12; a compute scan gives
// the same two tables in one dispatch per direction).

// Mirrored by `ScanParams` in server/passes/src/passes/cumulative_sums.rs.
struct ScanParams {
    width: u32,
    height: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<storage, read> params: ScanParams;
@group(0) @binding(1) var<storage, read> importance: array<f32>;
// Inclusive sums down each column, same layout as `importance` (row-major).
@group(0) @binding(2) var<storage, read_write> column_sums: array<f32>;
// Inclusive sums across the column totals (one entry per column).
@group(0) @binding(3) var<storage, read_write> row_sums: array<f32>;

const THREADS: u32 = 256u;
var<workgroup> partial: array<f32, 256>;

// Inclusive scan of `partial` (Hillis–Steele).
fn scan_partial(local: u32) {
    for (var offset = 1u; offset < THREADS; offset <<= 1u) {
        var add = 0.0;
        if local >= offset {
            add = partial[local - offset];
        }
        workgroupBarrier();
        partial[local] += add;
        workgroupBarrier();
    }
}

fn exclusive_prefix(local: u32) -> f32 {
    if local == 0u {
        return 0.0;
    }
    return partial[local - 1u];
}

// One workgroup per column; each thread sums a contiguous run of rows.
@compute @workgroup_size(256)
fn scan_columns(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let x = group.x;
    let w = params.width;
    let chunk = (params.height + THREADS - 1u) / THREADS;
    let start = min(local * chunk, params.height);
    let end = min(start + chunk, params.height);
    var s = 0.0;
    for (var y = start; y < end; y++) {
        s += importance[y * w + x];
    }
    partial[local] = s;
    workgroupBarrier();
    scan_partial(local);
    var running = exclusive_prefix(local);
    for (var y = start; y < end; y++) {
        running += importance[y * w + x];
        column_sums[y * w + x] = running;
    }
}

// One workgroup over the column totals.
@compute @workgroup_size(256)
fn scan_rows(@builtin(local_invocation_index) local: u32) {
    let w = params.width;
    let last_row = (params.height - 1u) * w;
    let chunk = (w + THREADS - 1u) / THREADS;
    let start = min(local * chunk, w);
    let end = min(start + chunk, w);
    var s = 0.0;
    for (var x = start; x < end; x++) {
        s += column_sums[last_row + x];
    }
    partial[local] = s;
    workgroupBarrier();
    scan_partial(local);
    var running = exclusive_prefix(local);
    for (var x = start; x < end; x++) {
        running += column_sums[last_row + x];
        row_sums[x] = running;
    }
}
