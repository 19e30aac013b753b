// VPL generation and k-means clustering into VALs (seed paper 003, §5–6), all in compute:
// `generate_vpls` (one thread per VPL), `seed_clusters` (one per cluster), then per iteration
// `assign` (one thread per VPL) and `update` (one workgroup per cluster), and after the last
// `assign` (the mapping C) `finalize`, which also measures each VAL's area.
//
// The paper scatters VPLs into the clusters with additive blending; here each cluster's
// workgroup gathers its VPLs in a fixed order instead, so that the same frame gives the same
// clusters bit for bit (blending order is not defined) at the same O(N·M) cost as `assign`.

@group(0) @binding(0) var<storage, read> params: ClusteredParams;
@group(0) @binding(1) var rsm_position: texture_2d<f32>;
@group(0) @binding(2) var rsm_normal: texture_2d<f32>;
@group(0) @binding(3) var rsm_flux_area: texture_2d<f32>;
@group(0) @binding(4) var<storage, read_write> vpls: array<Vpl>;
@group(0) @binding(5) var<storage, read_write> vals: array<Val>;
@group(0) @binding(6) var<storage, read_write> mapping: array<u32>;
@group(0) @binding(7) var rsm_glossy: texture_2d<u32>;
// Each VPL's glossy lobe, beside `vpls` (whose layout the paraboloid maps share with the VALs'):
// the texels' weight times their count, like `flux`.
@group(0) @binding(8) var<storage, read_write> vpl_glossy: array<GlossySender>;

// §6 "VPL Generation": the RSM fetched with point sampling at N Halton positions. Each VPL
// stands for 1/N of the atlas, so it carries the flux (and disk area) of W·H/N texels: the
// sum over all VPLs estimates the RSM's total.
@compute @workgroup_size(64)
fn generate_vpls(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.vpl_count {
        return;
    }
    let size = vec2<u32>(params.rsm_width, params.rsm_height);
    // Index 0 of the Halton sequence is the origin; start at 1.
    let h = vec2<f32>(halton(i + 1u, 2u), halton(i + 1u, 3u));
    let texel = min(vec2<u32>(h * vec2<f32>(size)), size - vec2<u32>(1u));
    let p = textureLoad(rsm_position, texel, 0);
    let fa = textureLoad(rsm_flux_area, texel, 0);
    var glossy = decode_glossy(textureLoad(rsm_glossy, texel, 0));
    let share = f32(params.rsm_width * params.rsm_height) / f32(params.vpl_count);
    // A metal texel reflects nothing diffusely, but its glossy lobe makes it a VPL.
    let lit = p.w > 0.0 && max(max(fa.r, max(fa.g, fa.b)), max(glossy.weight.r, max(glossy.weight.g, glossy.weight.b))) > 0.0;
    glossy.weight *= share;
    var vpl = Vpl(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0u, vec3<f32>(0.0), texel.y * size.x + texel.x);
    if lit {
        vpl.position = p.xyz;
        vpl.area = fa.a * share;
        vpl.normal = normalize(textureLoad(rsm_normal, texel, 0).xyz);
        vpl.lit = 1u;
        vpl.flux = fa.rgb * share;
    }
    vpls[i] = vpl;
    vpl_glossy[i] = glossy;
}

// §5.2 and §6 "Clustering": every frame restarts from the same initial assignment, never
// from the last frame's centres (which lose clusters as the light moves). The paper seeds
// cluster k with VPL k·N/M; with our Halton-ordered VPLs that stride is a poor pick: for N/M
// a power of two, Halton index k·N/M + 1 has the same low base-2 digits for every k, so all
// seeds fall in one column of the RSM (in the Cornell box 10 of 16 clusters stayed empty).
// Cluster k is seeded with VPL k instead: the first M Halton points are themselves spread
// over the whole RSM, and they are the same VPLs every frame. A seed without light (an empty
// or unlit RSM texel) is replaced by the next lit VPL k + j·M, so seeds stay distinct.
@compute @workgroup_size(64)
fn seed_clusters(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= params.cluster_count || params.keep_centres != 0u {
        return;
    }
    var val = Val(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0u, 0u, 0u, 0u, 0u);
    for (var i = k; i < params.vpl_count; i += params.cluster_count) {
        let vpl = vpls[i];
        if vpl.lit != 0u {
            val.position = vpl.position;
            val.normal = vpl.normal;
            val.centred = 1u;
            break;
        }
    }
    vals[k] = val;
}

// Each lit VPL to the centre at the smallest distance (§5.1); ties go to the lower index.
@compute @workgroup_size(64)
fn assign(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.vpl_count {
        return;
    }
    let vpl = vpls[i];
    var best = NO_VAL;
    var best_d = 0.0;
    if vpl.lit != 0u {
        for (var k = 0u; k < params.cluster_count; k++) {
            let c = vals[k];
            if c.centred == 0u {
                continue;
            }
            let d = cluster_distance(params, vpl, c);
            if best == NO_VAL || d < best_d {
                best = k;
                best_d = d;
            }
        }
    }
    mapping[i] = best;
}

const GROUP: u32 = 64u;
var<workgroup> sum_position: array<vec3<f32>, 64>;
var<workgroup> sum_normal: array<vec3<f32>, 64>;
var<workgroup> counts: array<u32, 64>;
var<workgroup> low: array<vec2<f32>, 64>;
var<workgroup> high: array<vec2<f32>, 64>;
var<workgroup> nearest_distance: array<f32, 64>;
var<workgroup> nearest: array<u32, 64>;

// Sums of the positions and normals of cluster k's VPLs, complete in slot 0. Each thread sums
// a fixed stride of the VPLs, then a tree halves the partial sums.
fn gather_members(k: u32, local: u32) {
    var p = vec3<f32>(0.0);
    var n = vec3<f32>(0.0);
    var c = 0u;
    for (var i = local; i < params.vpl_count; i += GROUP) {
        if mapping[i] == k {
            let vpl = vpls[i];
            p += vpl.position;
            n += vpl.normal;
            c += 1u;
        }
    }
    sum_position[local] = p;
    sum_normal[local] = n;
    counts[local] = c;
    workgroupBarrier();
    for (var span = GROUP / 2u; span > 0u; span /= 2u) {
        if local < span {
            sum_position[local] += sum_position[local + span];
            sum_normal[local] += sum_normal[local + span];
            counts[local] += counts[local + span];
        }
        workgroupBarrier();
    }
}

// The k-means update (§5.1): a centre moves to the mean of its VPLs. An empty cluster keeps
// its centre, so a VPL may still join it in the next iteration.
fn move_centre(k: u32) -> Val {
    var val = vals[k];
    val.count = counts[0];
    if counts[0] > 0u {
        val.position = sum_position[0] / f32(counts[0]);
        let n = sum_normal[0];
        // Opposite normals can cancel; the old direction is then as good as any.
        if dot(n, n) > 1e-12 {
            val.normal = normalize(n);
        }
    }
    return val;
}

@compute @workgroup_size(64)
fn update(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let k = group.x;
    gather_members(k, local);
    if local == 0u {
        vals[k] = move_centre(k);
    }
}

var<workgroup> centre: Val;

// The final VAL (§5, §6 "Clustering"): the mean normal of the VPLs C maps to it, as its area
// the 2D bounding rectangle of their positions projected onto the plane perpendicular to that
// mean normal, and as its position that of its VPL nearest to their mean (the lowest index
// among equals): the paper keeps the mean, but a mean can fall inside an object (VPLs on a
// floor and on a box top), whose paraboloid map would then shadow everything.
@compute @workgroup_size(64)
fn finalize(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let k = group.x;
    gather_members(k, local);
    if local == 0u {
        centre = move_centre(k);
    }
    workgroupBarrier();
    let c = centre;
    let basis = tangent_basis(c.normal);
    var lo = vec2<f32>(3.4e38);
    var hi = vec2<f32>(-3.4e38);
    var best = 3.4e38;
    var best_index = NO_VAL;
    for (var i = local; i < params.vpl_count; i += GROUP) {
        if mapping[i] == k {
            let d = vpls[i].position - c.position;
            let st = vec2<f32>(dot(d, basis[0]), dot(d, basis[1]));
            lo = min(lo, st);
            hi = max(hi, st);
            // Strides visit indices in increasing order: keep the first of equals.
            let l = length(d);
            if l < best {
                best = l;
                best_index = i;
            }
        }
    }
    low[local] = lo;
    high[local] = hi;
    nearest_distance[local] = best;
    nearest[local] = best_index;
    workgroupBarrier();
    for (var span = GROUP / 2u; span > 0u; span /= 2u) {
        if local < span {
            low[local] = min(low[local], low[local + span]);
            high[local] = max(high[local], high[local + span]);
            let a = local;
            let b = local + span;
            let other_wins = nearest_distance[b] < nearest_distance[a]
                || (nearest_distance[b] == nearest_distance[a] && nearest[b] < nearest[a]);
            if other_wins {
                nearest_distance[a] = nearest_distance[b];
                nearest[a] = nearest[b];
            }
        }
        workgroupBarrier();
    }
    if local == 0u {
        var val = c;
        val.area = 0.0;
        if c.count > 0u {
            let extent = high[0] - low[0];
            val.area = extent.x * extent.y;
            val.position = vpls[nearest[0]].position;
        }
        vals[k] = val;
    }
}
