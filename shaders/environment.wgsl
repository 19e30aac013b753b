// The frame's environment (light from infinitely far away), as
// server/passes/src/passes/environment.rs packs it into one array of f32 that the including
// shader binds as `environment`: a header (width and height as u32 bits; 0 × 0: none), then
// per texel its radiance (rgb) and the density per solid angle with which `env_sample` picks
// its directions, then the cumulative distribution over rows (height entries), then per row
// the one over its texels (width entries each).
//
// Texel (i, j) covers θ ∈ [π j/h, π (j+1)/h] from +Y and φ ∈ [2π i/w, 2π (i+1)/w], with
// d = (sin θ cos φ, cos θ, sin θ sin φ) (server/scene/src/environment.rs).

const ENV_HEADER: u32 = 4u;

fn env_width() -> u32 {
    return bitcast<u32>(environment[0]);
}

fn env_height() -> u32 {
    return bitcast<u32>(environment[1]);
}

fn env_enabled() -> bool {
    return env_width() > 0u;
}

// First word of the texel direction `d` (unit) falls in.
fn env_texel(d: vec3<f32>) -> u32 {
    let w = env_width();
    let h = env_height();
    let theta = acos(clamp(d.y, -1.0, 1.0));
    var phi = atan2(d.z, d.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let i = min(u32(phi / (2.0 * PI) * f32(w)), w - 1u);
    let j = min(u32(theta / PI * f32(h)), h - 1u);
    return ENV_HEADER + 4u * (j * w + i);
}

// Radiance arriving from direction `d` (unit); black without an environment.
fn env_radiance(d: vec3<f32>) -> vec3<f32> {
    if !env_enabled() {
        return vec3<f32>(0.0);
    }
    let k = env_texel(d);
    return vec3<f32>(environment[k], environment[k + 1u], environment[k + 2u]);
}

// Density per solid angle with which `env_sample` picks `d`.
fn env_pdf(d: vec3<f32>) -> f32 {
    if !env_enabled() {
        return 0.0;
    }
    return environment[env_texel(d) + 3u];
}

// Index of the first of `count` cumulative entries from word `first` above `u` (the last
// entry is 1, so u < 1 always finds one).
fn env_search(first: u32, count: u32, u: f32) -> u32 {
    var lo = 0u;
    var hi = count;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if environment[first + mid] <= u {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return min(lo, count - 1u);
}

struct EnvSample {
    direction: vec3<f32>,
    // Density per solid angle (0: the environment has no power there).
    pdf: f32,
    radiance: vec3<f32>,
}

// A texel by its power, then a direction uniform in its solid angle (cos θ uniform between
// its row's edges, φ between its column's, from where `u.y` fell in the texel's share of
// the row's distribution): the GPU twin of `EnvironmentMap::sample`.
fn env_sample(u: vec3<f32>) -> EnvSample {
    let w = env_width();
    let h = env_height();
    let rows = ENV_HEADER + 4u * w * h;
    let j = env_search(rows, h, u.x);
    let columns = rows + h + j * w;
    let i = env_search(columns, w, u.y);
    var below = 0.0;
    if i > 0u {
        below = environment[columns + i - 1u];
    }
    let share = environment[columns + i] - below;
    let along = select(0.5, clamp((u.y - below) / share, 0.0, 1.0), share > 0.0);
    let t0 = PI * f32(j) / f32(h);
    let t1 = PI * f32(j + 1u) / f32(h);
    let cos_theta = cos(t0) + (cos(t1) - cos(t0)) * u.z;
    let sin_theta = sqrt(max(1.0 - cos_theta * cos_theta, 0.0));
    let phi = 2.0 * PI * (f32(i) + along) / f32(w);
    let k = ENV_HEADER + 4u * (j * w + i);
    return EnvSample(
        vec3<f32>(sin_theta * cos(phi), cos_theta, sin_theta * sin(phi)),
        environment[k + 3u],
        vec3<f32>(environment[k], environment[k + 1u], environment[k + 2u]),
    );
}
