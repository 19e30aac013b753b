// Octahedral mapping of unit directions to the square [-1, 1]² (Cigolle et al. 2014, "A Survey
// of Efficient Representations for Independent Unit Vectors"). Mirrored by
// `lightcast_scene::octahedral`.

fn octahedral_encode(d: vec3<f32>) -> vec2<f32> {
    let p = d.xy / (abs(d.x) + abs(d.y) + abs(d.z));
    if d.z >= 0.0 {
        return p;
    }
    return (vec2<f32>(1.0) - abs(p.yx)) * select(vec2<f32>(-1.0), vec2<f32>(1.0), p >= vec2<f32>(0.0));
}

fn octahedral_decode(e: vec2<f32>) -> vec3<f32> {
    var d = vec3<f32>(e, 1.0 - abs(e.x) - abs(e.y));
    let t = max(-d.z, 0.0);
    d.x += select(t, -t, d.x >= 0.0);
    d.y += select(t, -t, d.y >= 0.0);
    return normalize(d);
}
