//! The scene's node hierarchy, kept beside its world-space triangles (issue 35): which parts a
//! client may move, the vertices each one moves, and the glTF file's animations of them.
//!
//! The triangles stay in world space at the nodes' rest pose (every pass reads them so); a
//! node carries the range of vertices of its subtree, which is one range because the loaders
//! append a node's own geometry and then each child's subtree in turn (preorder).

use crate::Aabb;
use glam::{Mat4, Quat, Vec3};
use std::ops::Range;

/// A node's transform relative to its parent: glTF's translation, rotation and scale.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    pub translation: Vec3,
    pub rotation: Quat,
    pub scale: Vec3,
}

impl Transform {
    pub const IDENTITY: Self = Self {
        translation: Vec3::ZERO,
        rotation: Quat::IDENTITY,
        scale: Vec3::ONE,
    };

    pub fn matrix(&self) -> Mat4 {
        Mat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }

    /// The transform `m` is, when it is one (no shear, finite): glTF allows a node's `matrix`
    /// to be any affine map, but only translation, rotation and scale can be animated or set.
    pub fn from_matrix(m: &Mat4) -> Option<Self> {
        let (scale, rotation, translation) = m.to_scale_rotation_translation();
        let t = Self {
            translation,
            rotation,
            scale,
        };
        let back = t.matrix();
        let tolerance = 1e-4 * m.to_cols_array().iter().fold(1.0f32, |a, c| a.max(c.abs()));
        (t.is_finite() && back.abs_diff_eq(*m, tolerance)).then_some(t)
    }

    pub fn is_finite(&self) -> bool {
        self.translation.is_finite() && self.rotation.is_finite() && self.scale.is_finite()
    }
}

/// One node: a glTF node, or a part of a procedural scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    /// What clients name it by: the glTF node's index, or the procedural part's number.
    pub id: u32,
    pub name: String,
    /// The parent's id (`None` for a root).
    pub parent: Option<u32>,
    /// Whether clients may pose it (its subtree moves with it): a procedural scene's movable
    /// parts, and in a glTF file every node an animation's translation, rotation or scale
    /// targets or whose `extras` say `"movable": true`, and their descendants that have a
    /// translation, rotation and scale (the others move with them: see [`can_move`]).
    pub movable: bool,
    /// Relative to the parent, as authored (its rest pose); `None` for a glTF `matrix` that
    /// is no translation, rotation and scale (such a node cannot be movable).
    pub local: Option<Transform>,
    /// The world transform at rest: the triangles' vertices are already in it.
    pub rest_world: Mat4,
    /// The vertices of the subtree (see the module's documentation).
    pub vertices: Range<u32>,
}

/// What a glTF animation channel drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Property {
    Translation,
    Rotation,
    Scale,
    /// Morph target weights: listed, not played.
    Weights,
}

/// A sampler's interpolation (glTF 2.0 §3.11).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    Linear,
    Step,
    CubicSpline,
}

/// One animated property of one node.
#[derive(Clone, Debug, PartialEq)]
pub struct Channel {
    pub node: u32,
    pub property: Property,
    pub interpolation: Interpolation,
    /// Key times in seconds, non-decreasing.
    pub times: Vec<f32>,
    /// Per key: the value (3 components, 4 for a rotation's quaternion, the morph target
    /// count for weights), or for a cubic spline in-tangent, value and out-tangent.
    pub values: Vec<f32>,
}

impl Channel {
    /// Components of one value.
    pub fn width(&self) -> usize {
        let elements = match self.interpolation {
            Interpolation::CubicSpline => 3,
            _ => 1,
        };
        self.values.len() / (self.times.len() * elements).max(1)
    }
}

impl Channel {
    /// The value at time `t` (seconds; before the first key the first value, after the last
    /// the last), interpolated as glTF 2.0 §3.11 says: linear (spherical for rotations), step,
    /// or the cubic Hermite spline through the keys with their tangents; rotations come out
    /// normalised.
    pub fn sample(&self, t: f32) -> Vec<f32> {
        let w = self.width();
        let cubic = self.interpolation == Interpolation::CubicSpline;
        // Key k's value (the middle of in-tangent, value, out-tangent for a spline).
        let value = |k: usize, part: usize| -> &[f32] {
            let start = if cubic { (3 * k + part) * w } else { k * w };
            &self.values[start..start + w]
        };
        let last = self.times.len() - 1;
        let k = self.times.partition_point(|&key| key <= t);
        let out: Vec<f32> = if k == 0 {
            value(0, 1).to_vec()
        } else if k > last {
            value(last, 1).to_vec()
        } else {
            let (t0, t1) = (self.times[k - 1], self.times[k]);
            let dt = t1 - t0;
            let s = ((t - t0) / dt).clamp(0.0, 1.0);
            match self.interpolation {
                Interpolation::Step => value(k - 1, 1).to_vec(),
                Interpolation::Linear if self.property == Property::Rotation => {
                    let (a, b) = (value(k - 1, 1), value(k, 1));
                    let qa = Quat::from_slice(a).normalize();
                    let qb = Quat::from_slice(b).normalize();
                    qa.slerp(qb, s).to_array().to_vec()
                }
                Interpolation::Linear => {
                    let (a, b) = (value(k - 1, 1), value(k, 1));
                    a.iter().zip(b).map(|(a, b)| a + (b - a) * s).collect()
                }
                Interpolation::CubicSpline => {
                    let (s2, s3) = (s * s, s * s * s);
                    let (h00, h10) = (2.0 * s3 - 3.0 * s2 + 1.0, s3 - 2.0 * s2 + s);
                    let (h01, h11) = (-2.0 * s3 + 3.0 * s2, s3 - s2);
                    let (v0, b0) = (value(k - 1, 1), value(k - 1, 2));
                    let (v1, a1) = (value(k, 1), value(k, 0));
                    (0..w)
                        .map(|i| h00 * v0[i] + h10 * dt * b0[i] + h01 * v1[i] + h11 * dt * a1[i])
                        .collect()
                }
            }
        };
        if self.property == Property::Rotation {
            let q = Quat::from_slice(&out);
            return if q.length() > 0.0 {
                q.normalize().to_array().to_vec()
            } else {
                Quat::IDENTITY.to_array().to_vec()
            };
        }
        out
    }
}

/// A glTF animation.
#[derive(Clone, Debug, PartialEq)]
pub struct Animation {
    pub name: String,
    pub channels: Vec<Channel>,
}

impl Animation {
    /// Seconds from 0 to its last key.
    pub fn duration(&self) -> f32 {
        self.channels
            .iter()
            .filter_map(|c| c.times.last().copied())
            .fold(0.0, f32::max)
    }

    /// The local transforms of the nodes it moves at time `t`: each node's own, with the
    /// properties its channels drive sampled at `t` (morph weights are not played).
    pub fn locals_at(&self, nodes: &[Node], t: f32) -> Vec<(u32, Transform)> {
        let mut out: Vec<(u32, Transform)> = Vec::new();
        let at: std::collections::HashMap<u32, usize> =
            nodes.iter().enumerate().map(|(i, n)| (n.id, i)).collect();
        for c in &self.channels {
            if c.property == Property::Weights {
                continue;
            }
            let Some(own) = at.get(&c.node).and_then(|&n| nodes[n].local) else {
                continue;
            };
            let slot = match out.iter().position(|(id, _)| *id == c.node) {
                Some(i) => i,
                None => {
                    out.push((c.node, own));
                    out.len() - 1
                }
            };
            let v = c.sample(t);
            let t = &mut out[slot].1;
            match c.property {
                Property::Translation => t.translation = Vec3::from_slice(&v),
                Property::Rotation => t.rotation = Quat::from_slice(&v),
                Property::Scale => t.scale = Vec3::from_slice(&v),
                Property::Weights => {}
            }
        }
        out
    }
}

/// Why a scene's nodes do not fit its vertices.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum NodeError {
    #[error("node {0}: its id is used twice")]
    DuplicateId(u32),
    #[error("node {node}: parent {parent} is not listed before it")]
    Parent { node: u32, parent: u32 },
    #[error("node {node}: vertices {start}..{end} do not lie within {limit}")]
    Vertices {
        node: u32,
        start: u32,
        end: u32,
        limit: String,
    },
    #[error("triangle {0} joins vertices of two nodes")]
    Straddles(usize),
    #[error("node {0}: its vertices start before the node listed before it")]
    Order(u32),
    #[error("animation '{animation}': targets node {node}, which the scene does not list")]
    Target { animation: String, node: u32 },
}

/// Checks that `nodes` (each listed after its parent, their vertex ranges starting in list
/// order) nest their vertex ranges within their parents' and within `vertex_count`, and that
/// no triangle of `indices` joins vertices whose innermost nodes differ (moving one would
/// stretch it).
pub fn validate(
    nodes: &[Node],
    animations: &[Animation],
    vertex_count: u32,
    indices: &[u32],
) -> Result<(), NodeError> {
    let mut seen: std::collections::HashMap<u32, usize> = std::collections::HashMap::new();
    for (i, node) in nodes.iter().enumerate() {
        let within = match node.parent {
            None => 0..vertex_count,
            Some(parent) => {
                let &p = seen.get(&parent).ok_or(NodeError::Parent {
                    node: node.id,
                    parent,
                })?;
                nodes[p].vertices.clone()
            }
        };
        let v = &node.vertices;
        if v.start > v.end || v.start < within.start || v.end > within.end {
            return Err(NodeError::Vertices {
                node: node.id,
                start: v.start,
                end: v.end,
                limit: match node.parent {
                    None => format!("the scene's {vertex_count} vertices"),
                    Some(parent) => format!("parent {parent}'s {}..{}", within.start, within.end),
                },
            });
        }
        if seen.insert(node.id, i).is_some() {
            return Err(NodeError::DuplicateId(node.id));
        }
        if i > 0 && v.start < nodes[i - 1].vertices.start {
            return Err(NodeError::Order(node.id));
        }
    }
    let owner = owners(nodes, vertex_count);
    let owner_of = |v: u32| owner.get(v as usize).copied().unwrap_or(u32::MAX);
    for (t, tri) in indices.chunks_exact(3).enumerate() {
        if tri.iter().any(|&v| owner_of(v) != owner_of(tri[0])) {
            return Err(NodeError::Straddles(t));
        }
    }
    for a in animations {
        if let Some(c) = a.channels.iter().find(|c| !seen.contains_key(&c.node)) {
            return Err(NodeError::Target {
                animation: a.name.clone(),
                node: c.node,
            });
        }
    }
    Ok(())
}

/// Whether each node (in `nodes`' order) can move: it is movable or lies under a movable one.
pub fn can_move(nodes: &[Node]) -> Vec<bool> {
    let at: std::collections::HashMap<u32, usize> =
        nodes.iter().enumerate().map(|(i, n)| (n.id, i)).collect();
    let mut moves = vec![false; nodes.len()];
    for (i, node) in nodes.iter().enumerate() {
        moves[i] = node.movable
            || node
                .parent
                .and_then(|p| at.get(&p))
                .is_some_and(|&p| moves[p]);
    }
    moves
}

/// `lights` (a scene's first lights, carried by `light_nodes`: [`crate::Scene::light_nodes`])
/// where `poses` put the nodes carrying them: position and direction moved by the node's change
/// from rest. A light whose node stays where it is comes back as it was, bit for bit.
pub fn posed_lights(
    nodes: &[Node],
    lights: &[lightcast_protocol::Light],
    light_nodes: &[Option<u32>],
    poses: &Poses,
) -> Vec<lightcast_protocol::Light> {
    if poses.is_empty() || light_nodes.iter().all(Option::is_none) {
        return lights.to_vec();
    }
    let worlds = posed_worlds(nodes, poses);
    lights
        .iter()
        .enumerate()
        .map(|(i, light)| {
            let carrier = light_nodes
                .get(i)
                .copied()
                .flatten()
                .and_then(|id| nodes.iter().position(|n| n.id == id))
                .filter(|&n| worlds[n] != nodes[n].rest_world);
            let Some(n) = carrier else {
                return light.clone();
            };
            let delta = worlds[n] * nodes[n].rest_world.inverse();
            let direction = Vec3::from(light.direction);
            lightcast_protocol::Light {
                position: delta.transform_point3(light.position.into()).to_array(),
                direction: delta
                    .transform_vector3(direction)
                    .try_normalize()
                    .unwrap_or(direction)
                    .to_array(),
                ..light.clone()
            }
        })
        .collect()
}

/// What a click on a surface of `vertex` picks (positions in `nodes`' order): the innermost
/// node holding the vertex, and the node dragging it moves, its outermost movable ancestor or
/// itself (`None` where nothing above it moves: a wheel drags its car). `None` where no node
/// holds the vertex.
pub fn picked(nodes: &[Node], vertex: u32) -> Option<(usize, Option<usize>)> {
    // Preorder with nested ranges: the last node holding the vertex is the innermost.
    let inner = nodes.iter().rposition(|n| n.vertices.contains(&vertex))?;
    let mut mover = None;
    let mut at = Some(inner);
    while let Some(i) = at {
        if nodes[i].movable {
            mover = Some(i);
        }
        at = nodes[i]
            .parent
            .and_then(|p| nodes[..i].iter().rposition(|n| n.id == p));
    }
    Some((inner, mover))
}

/// Each vertex's innermost node (its position in `nodes`; `u32::MAX` for none), for nodes
/// [`validate`] accepts: one sweep over the vertices with a stack of the open ranges, so a
/// deep hierarchy costs no more than a flat one.
pub fn owners(nodes: &[Node], vertex_count: u32) -> Vec<u32> {
    let mut owner = vec![u32::MAX; vertex_count as usize];
    let mut open: Vec<usize> = Vec::new();
    let mut next = 0;
    for (v, o) in owner.iter_mut().enumerate() {
        let v = v as u32;
        while next < nodes.len() && nodes[next].vertices.start <= v {
            open.push(next);
            next += 1;
        }
        while open.last().is_some_and(|&n| nodes[n].vertices.end <= v) {
            open.pop();
        }
        if let Some(&n) = open.last() {
            *o = n as u32;
        }
    }
    owner
}

/// Every node's subtree bounds at rest, in `nodes`' order (`None` without geometry):
/// each vertex counted once, at its innermost node, then folded up into the parents.
pub fn subtree_bounds(nodes: &[Node], positions: &[Vec3]) -> Vec<Option<Aabb>> {
    let mut bounds: Vec<Option<Aabb>> = vec![None; nodes.len()];
    let grow = |b: &mut Option<Aabb>, other: Aabb| {
        *b = Some(match *b {
            None => other,
            Some(b) => Aabb {
                min: b.min.min(other.min),
                max: b.max.max(other.max),
            },
        });
    };
    for (&o, &p) in owners(nodes, positions.len() as u32).iter().zip(positions) {
        if let Some(b) = bounds.get_mut(o as usize) {
            grow(b, Aabb { min: p, max: p });
        }
    }
    let at: std::collections::HashMap<u32, usize> =
        nodes.iter().enumerate().map(|(i, n)| (n.id, i)).collect();
    for i in (0..nodes.len()).rev() {
        let parent = nodes[i].parent.and_then(|p| at.get(&p).copied());
        if let (Some(p), Some(b)) = (parent, bounds[i]) {
            grow(&mut bounds[p], b);
        }
    }
    bounds
}

/// Movable nodes' local transforms replacing their own (a `render.nodes` list resolved by
/// [`resolve_poses`]), sorted by node id.
pub type Poses = Vec<(u32, Transform)>;

/// Most entries `render.nodes` may hold.
pub const MAX_POSES: usize = 1024;
/// The range of each scale component of a pose.
pub const SCALE_RANGE: (f32, f32) = (1e-3, 1e3);

/// A `render.nodes` entry that cannot be used: `index` is its position (`None`: the list),
/// `field` the field at fault.
#[derive(Debug, PartialEq)]
pub struct PoseError {
    pub index: Option<usize>,
    pub field: &'static str,
    pub reason: String,
}

/// Checks `requested` against the scene's `nodes` (their subtree `bounds` at rest, from
/// [`subtree_bounds`]) and resolves every entry to a whole local transform (fields left out
/// are the node's own). A pose must keep its node within `scene_bounds`: the light and shadow
/// maps are fitted to them, and beyond them would clip the node. An entry without fields
/// puts its node back (it is left out); one whose fields leave the node where it is stays in
/// the list: it pins the node against an animation, and [`merge_poses`] drops it from a
/// frame's poses.
pub fn resolve_poses(
    nodes: &[Node],
    bounds: &[Option<Aabb>],
    scene_bounds: &Aabb,
    requested: &[lightcast_protocol::NodePose],
) -> Result<Poses, PoseError> {
    let error = |index, field, reason: String| PoseError {
        index: Some(index),
        field,
        reason,
    };
    if requested.len() > MAX_POSES {
        return Err(PoseError {
            index: None,
            field: "",
            reason: format!(
                "{} entries; at most {MAX_POSES} (one per movable node)",
                requested.len()
            ),
        });
    }
    let at: std::collections::HashMap<u32, usize> =
        nodes.iter().enumerate().map(|(i, n)| (n.id, i)).collect();
    let mut poses: Poses = Vec::with_capacity(requested.len());
    for (i, pose) in requested.iter().enumerate() {
        let Some(node) = at.get(&pose.node).map(|&n| &nodes[n]) else {
            return Err(error(
                i,
                "node",
                format!("the scene has no node {}", pose.node),
            ));
        };
        let (true, Some(own)) = (node.movable, node.local) else {
            return Err(error(
                i,
                "node",
                format!("node {} ('{}') is not movable", node.id, node.name),
            ));
        };
        if requested[..i].iter().any(|p| p.node == pose.node) {
            return Err(error(
                i,
                "node",
                format!("node {} is listed twice", pose.node),
            ));
        }
        let limit = crate::MAX_SCENE_EXTENT;
        let translation = match pose.translation.map(Vec3::from) {
            None => own.translation,
            Some(t) if t.is_finite() && t.abs().max_element() <= limit => t,
            Some(t) => {
                return Err(error(
                    i,
                    "translation",
                    format!("{t} must be finite and within ±{limit:e}"),
                ))
            }
        };
        let rotation = match pose.rotation.map(Quat::from_array) {
            None => own.rotation,
            // A unit quaternion is kept as given: normalising it again may change its last
            // bit, and a node's own rotation sent back must leave it where it is.
            Some(q) if q.is_finite() && (q.length() - 1.0).abs() < 1e-6 => q,
            Some(q) if q.is_finite() && q.length() > 1e-6 => q.normalize(),
            Some(q) => {
                return Err(error(
                    i,
                    "rotation",
                    format!("{q} must be a finite, non-zero quaternion [x, y, z, w]"),
                ))
            }
        };
        let (lo, hi) = SCALE_RANGE;
        let scale = match pose.scale.map(Vec3::from) {
            None => own.scale,
            Some(s) if s.is_finite() && s.min_element() >= lo && s.max_element() <= hi => s,
            Some(s) => {
                return Err(error(
                    i,
                    "scale",
                    format!("{s}: each component must be within [{lo}, {hi}]"),
                ))
            }
        };
        if pose.translation.is_some() || pose.rotation.is_some() || pose.scale.is_some() {
            poses.push((
                pose.node,
                Transform {
                    translation,
                    rotation,
                    scale,
                },
            ));
        }
    }
    poses.sort_by_key(|(id, _)| *id);
    let worlds = posed_worlds(nodes, &poses);
    let grown = {
        let slack = Vec3::splat(1e-4 * (scene_bounds.max - scene_bounds.min).max_element());
        Aabb {
            min: scene_bounds.min - slack,
            max: scene_bounds.max + slack,
        }
    };
    for (i, pose) in requested.iter().enumerate() {
        let Some(&n) = at.get(&pose.node) else {
            continue;
        };
        let delta = worlds[n] * nodes[n].rest_world.inverse();
        // `!(… > 0)`: a singular rest world (a zero-scale ancestor) makes NaNs, refused too.
        if !(delta.determinant() > 0.0 && delta.is_finite()) {
            return Err(error(
                i,
                "scale",
                "would mirror the node (its own transform mirrors; give a scale that keeps it)"
                    .into(),
            ));
        }
        if let Some(b) = bounds[n] {
            let moved = corners(&b).map(|c| delta.transform_point3(c));
            if moved
                .iter()
                .any(|c| c.cmplt(grown.min).any() || c.cmpgt(grown.max).any())
            {
                return Err(error(
                    i,
                    "translation",
                    format!(
                        "moves node {} outside the scene's bounds ({} … {}), to which its light \
                         and shadow maps are fitted",
                        pose.node, scene_bounds.min, scene_bounds.max
                    ),
                ));
            }
        }
    }
    Ok(poses)
}

/// A frame's poses: an animation's (`Animation::locals_at`; none without one) with `explicit`
/// ones (from [`resolve_poses`]) over them, sorted by id, without the entries that leave a
/// node where it is (a node put back moves nothing, and needs no method that follows).
pub fn merge_poses(nodes: &[Node], animated: Vec<(u32, Transform)>, explicit: &Poses) -> Poses {
    let at: std::collections::HashMap<u32, usize> =
        nodes.iter().enumerate().map(|(i, n)| (n.id, i)).collect();
    let mut out: Poses = animated
        .into_iter()
        .filter(|(id, _)| explicit.binary_search_by_key(id, |(e, _)| *e).is_err())
        .chain(explicit.iter().copied())
        .filter(|(id, t)| at.get(id).is_some_and(|&n| nodes[n].local != Some(*t)))
        .collect();
    out.sort_by_key(|(id, _)| *id);
    out
}

/// Most times [`animation_reach`] places an animation's nodes at.
const REACH_SAMPLES: usize = 256;
/// Most node placements [`animation_reach`] does over all animations (a time costs one per
/// node): about a second of work whatever a file holds.
const REACH_WORK: usize = 1 << 26;

/// The world bounds every animation moves its nodes through: their subtrees' `bounds` (from
/// [`subtree_bounds`]) placed at each key and half-way between keys (a slerp or a spline can
/// leave the keys' hull a little; the half-way samples catch most of that), at most
/// [`REACH_SAMPLES`] of those times per animation and [`REACH_WORK`] placements in all,
/// evenly spread, the last key always.
pub fn animation_reach(
    nodes: &[Node],
    animations: &[Animation],
    bounds: &[Option<Aabb>],
) -> Option<Aabb> {
    let mut reach: Option<Aabb> = None;
    for animation in animations {
        let mut times: Vec<f32> = animation
            .channels
            .iter()
            .flat_map(|c| {
                c.times
                    .iter()
                    .copied()
                    .chain(c.times.windows(2).map(|w| 0.5 * (w[0] + w[1])))
            })
            .collect();
        times.sort_by(f32::total_cmp);
        times.dedup();
        let budget =
            (REACH_WORK / nodes.len().max(1) / animations.len().max(1)).clamp(1, REACH_SAMPLES);
        let step = times.len().div_ceil(budget).max(1);
        let last = times.last().copied();
        // Evenly spread, and the last key (often the farthest pose) always.
        let sampled = times.iter().copied().step_by(step).chain(last);
        for t in sampled {
            let poses = merge_poses(nodes, animation.locals_at(nodes, t), &Poses::new());
            let worlds = posed_worlds(nodes, &poses);
            // A moved node's subtree holds everything that moves with it.
            for (n, node) in nodes.iter().enumerate() {
                if poses.binary_search_by_key(&node.id, |(id, _)| *id).is_err() {
                    continue;
                }
                let Some(b) = bounds[n] else { continue };
                let delta = worlds[n] * node.rest_world.inverse();
                for c in corners(&b).map(|c| delta.transform_point3(c)) {
                    reach = Some(match reach {
                        None => Aabb { min: c, max: c },
                        Some(r) => Aabb {
                            min: r.min.min(c),
                            max: r.max.max(c),
                        },
                    });
                }
            }
        }
    }
    reach
}

fn corners(b: &Aabb) -> [Vec3; 8] {
    std::array::from_fn(|k| {
        Vec3::new(
            if k & 1 == 0 { b.min.x } else { b.max.x },
            if k & 2 == 0 { b.min.y } else { b.max.y },
            if k & 4 == 0 { b.min.z } else { b.max.z },
        )
    })
}

/// Every node's world transform with `poses` (sorted by id) in place of their own local
/// transforms, in `nodes`' order (parents before children).
pub fn posed_worlds(nodes: &[Node], poses: &[(u32, Transform)]) -> Vec<Mat4> {
    let mut worlds: Vec<Mat4> = Vec::with_capacity(nodes.len());
    // Whether a node or an ancestor is posed: the others keep their rest world bit for bit
    // (a product through the parents would be a few ulps off it).
    let mut moved: Vec<bool> = Vec::with_capacity(nodes.len());
    let at: std::collections::HashMap<u32, usize> =
        nodes.iter().enumerate().map(|(i, n)| (n.id, i)).collect();
    for node in nodes {
        let up = node.parent.and_then(|p| at.get(&p)).copied();
        let parent = up.filter(|&p| moved[p]).map(|p| worlds[p]);
        let posed = poses
            .binary_search_by_key(&node.id, |(id, _)| *id)
            .ok()
            .map(|k| &poses[k].1);
        moved.push(posed.is_some() || parent.is_some());
        let world = match (posed, parent) {
            // Unposed: the rest pose, moved with its parent.
            (None, None) => node.rest_world,
            (None, Some(parent)) => {
                let rest_parent = node
                    .parent
                    .and_then(|p| at.get(&p))
                    .map_or(Mat4::IDENTITY, |&p| nodes[p].rest_world);
                parent * rest_parent.inverse() * node.rest_world
            }
            (Some(t), parent) => {
                // The parent's world at rest, as the node's own rest world implies it.
                let parent = parent.or(up.map(|p| worlds[p])).unwrap_or_else(|| {
                    node.rest_world * node.local.map_or(Mat4::IDENTITY, |l| l.matrix()).inverse()
                });
                parent * t.matrix()
            }
        };
        worlds.push(world);
    }
    worlds
}

/// A node's change from its rest world, and that change's inverse transpose for normals.
pub type Delta = (Mat4, glam::Mat3);

/// Every node's [`Delta`] for `worlds` (from [`posed_worlds`]); `None` where the node is at
/// rest (its vertices stay bit for bit).
pub fn deltas(nodes: &[Node], worlds: &[Mat4]) -> Vec<Option<Delta>> {
    nodes
        .iter()
        .zip(worlds)
        .map(|(n, w)| {
            (*w != n.rest_world).then(|| {
                let delta = *w * n.rest_world.inverse();
                (delta, glam::Mat3::from_mat4(delta).inverse().transpose())
            })
        })
        .collect()
}

/// The scene's vertices `range` moved by `deltas` (from [`deltas`]): each vertex by its
/// innermost node's (`owner` from [`owners`]), its normal by the inverse transpose.
pub fn posed_vertices(
    vertices: &[crate::Vertex],
    owner: &[u32],
    deltas: &[Option<Delta>],
    range: Range<u32>,
) -> Vec<crate::Vertex> {
    (range.start as usize..range.end as usize)
        .map(|v| {
            let mut out = vertices[v];
            if let Some(Some((delta, normals))) = deltas.get(owner[v] as usize) {
                out.position = delta.transform_point3(out.position.into()).to_array();
                out.normal = (*normals * Vec3::from(out.normal))
                    .try_normalize()
                    .unwrap_or(Vec3::Y)
                    .to_array();
            }
            out
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(id: u32, parent: Option<u32>, vertices: Range<u32>) -> Node {
        Node {
            id,
            name: format!("n{id}"),
            parent,
            movable: true,
            local: Some(Transform::IDENTITY),
            rest_world: Mat4::IDENTITY,
            vertices,
        }
    }

    #[test]
    fn bounds_fold_up_a_deep_hierarchy_in_one_sweep() {
        // A chain of 10,000 nodes, each holding one vertex of its own and the chain below.
        let n = 10_000u32;
        let nodes: Vec<Node> = (0..n).map(|i| node(i, i.checked_sub(1), i..n)).collect();
        let positions: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(i as f32, 0.0, -(i as f32)))
            .collect();
        assert_eq!(validate(&nodes, &[], n, &[]), Ok(()));
        let bounds = subtree_bounds(&nodes, &positions);
        let deepest = bounds[n as usize - 1].expect("one vertex");
        assert_eq!(
            (deepest.min, deepest.max),
            (positions[9_999], positions[9_999])
        );
        let root = bounds[0].expect("all");
        assert_eq!(root.min, Vec3::new(0.0, 0.0, -9_999.0));
        assert_eq!(root.max, Vec3::new(9_999.0, 0.0, 0.0));
        let mut swapped = vec![
            node(0, None, 0..10),
            node(1, Some(0), 5..6),
            node(2, Some(0), 2..3),
        ];
        assert_eq!(validate(&swapped, &[], 10, &[]), Err(NodeError::Order(2)));
        swapped.swap(1, 2);
        assert_eq!(validate(&swapped, &[], 10, &[]), Ok(()));
    }

    #[test]
    fn a_click_picks_the_innermost_node_and_drags_its_outermost_movable_one() {
        // 0 static world [0, 10) ⊃ 1 car [2, 8) ⊃ 2 wheel [4, 6); 3 static shed [8, 10).
        let mut nodes = vec![
            node(0, None, 0..10),
            node(1, Some(0), 2..8),
            node(2, Some(1), 4..6),
            node(3, Some(0), 8..10),
        ];
        nodes[0].movable = false;
        nodes[3].movable = false;
        assert_eq!(validate(&nodes, &[], 10, &[]), Ok(()));
        assert_eq!(picked(&nodes, 5), Some((2, Some(1))));
        assert_eq!(picked(&nodes, 3), Some((1, Some(1))));
        assert_eq!(picked(&nodes, 1), Some((0, None)));
        assert_eq!(picked(&nodes, 9), Some((3, None)));
        assert_eq!(picked(&nodes, 10), None);
        // A movable wheel on a static car drags itself.
        nodes[1].movable = false;
        nodes[2].movable = true;
        assert_eq!(picked(&nodes, 5), Some((2, Some(2))));
    }

    fn pose(node: u32) -> lightcast_protocol::NodePose {
        lightcast_protocol::NodePose {
            node,
            translation: None,
            rotation: None,
            scale: None,
        }
    }

    #[test]
    fn a_posed_box_moves_its_vertices_and_normals_and_nothing_else() {
        let scene = crate::procedural::cornell_box();
        let bounds = scene.node_bounds();
        let short = scene.node(1).expect("short box").clone();
        let base = short.local.expect("TRS").translation;
        // A quarter turn about its own vertical axis, 10 cm towards the back.
        let requested = [lightcast_protocol::NodePose {
            translation: Some((base - Vec3::Z * 0.1).to_array()),
            rotation: Some(Quat::from_rotation_y(std::f32::consts::FRAC_PI_2).to_array()),
            ..pose(1)
        }];
        let poses =
            resolve_poses(&scene.nodes, &bounds, &scene.bounds, &requested).expect("a valid pose");
        let worlds = posed_worlds(&scene.nodes, &poses);
        let owner = owners(&scene.nodes, scene.vertices.len() as u32);
        let all = 0..scene.vertices.len() as u32;
        let moved = posed_vertices(&scene.vertices, &owner, &deltas(&scene.nodes, &worlds), all);
        let turn = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
        for (i, (was, now)) in scene.vertices.iter().zip(&moved).enumerate() {
            let (p, n) = (Vec3::from(was.position), Vec3::from(was.normal));
            let (want_p, want_n) = if short.vertices.contains(&(i as u32)) {
                (base - Vec3::Z * 0.1 + turn * (p - base), turn * n)
            } else {
                (p, n)
            };
            assert!(Vec3::from(now.position).abs_diff_eq(want_p, 1e-5), "{i}");
            assert!(Vec3::from(now.normal).abs_diff_eq(want_n, 1e-5), "{i}");
        }
        // Unposed, every vertex is where it was.
        let rest = posed_worlds(&scene.nodes, &[]);
        let same = posed_vertices(&scene.vertices, &owner, &deltas(&scene.nodes, &rest), 0..10);
        assert_eq!(same, scene.vertices[..10]);
    }

    #[test]
    fn poses_that_cannot_be_used_are_refused_naming_the_field() {
        let scene = crate::procedural::cornell_box();
        let bounds = scene.node_bounds();
        let check = |requested: &[lightcast_protocol::NodePose]| {
            resolve_poses(&scene.nodes, &bounds, &scene.bounds, requested)
                .map(|_| ())
                .map_err(|e| (e.index, e.field, e.reason))
        };
        let refused = |requested: &[lightcast_protocol::NodePose], index, field, says: &str| {
            let (i, f, reason) = check(requested).expect_err("refused");
            assert_eq!((i, f), (index, field), "{reason}");
            assert!(reason.contains(says), "{reason}");
        };
        assert_eq!(check(&[pose(1), pose(2)]), Ok(()));
        refused(&[pose(7)], Some(0), "node", "no node 7");
        refused(
            &[pose(1), pose(0)],
            Some(1),
            "node",
            "node 0 ('room') is not movable",
        );
        refused(&[pose(2), pose(2)], Some(1), "node", "listed twice");
        let with = |f: fn(&mut lightcast_protocol::NodePose)| {
            let mut p = pose(1);
            f(&mut p);
            [p]
        };
        refused(
            &with(|p| p.translation = Some([f32::NAN, 0.0, 0.0])),
            Some(0),
            "translation",
            "finite",
        );
        refused(
            &with(|p| p.translation = Some([0.0, 0.0, 1e9])),
            Some(0),
            "translation",
            "within",
        );
        refused(
            &with(|p| p.rotation = Some([0.0; 4])),
            Some(0),
            "rotation",
            "non-zero",
        );
        refused(
            &with(|p| p.scale = Some([1.0, 0.0, 1.0])),
            Some(0),
            "scale",
            "within",
        );
        refused(
            &with(|p| p.scale = Some([1.0, 1e6, 1.0])),
            Some(0),
            "scale",
            "within",
        );
        // Out through the open front wall, past the room's bounds.
        refused(
            &with(|p| p.translation = Some([0.0, 0.0, 3.0])),
            Some(0),
            "translation",
            "outside the scene's bounds",
        );
        let many: Vec<_> = (0..=MAX_POSES as u32).map(pose).collect();
        refused(&many, None, "", "at most 1024");
    }

    fn channel(
        property: Property,
        interpolation: Interpolation,
        times: &[f32],
        values: &[f32],
    ) -> Channel {
        Channel {
            node: 1,
            property,
            interpolation,
            times: times.to_vec(),
            values: values.to_vec(),
        }
    }

    /// glTF 2.0 §3.11's interpolations against values worked out by hand.
    #[test]
    fn channels_sample_as_gltf_interpolates() {
        let slide = channel(
            Property::Translation,
            Interpolation::Linear,
            &[1.0, 3.0],
            &[0.0, 0.0, 0.0, 4.0, 2.0, -2.0],
        );
        assert_eq!(slide.sample(2.0), [2.0, 1.0, -1.0]);
        assert_eq!(slide.sample(0.0), [0.0, 0.0, 0.0], "before the first key");
        assert_eq!(slide.sample(9.0), [4.0, 2.0, -2.0], "after the last key");
        let step = channel(
            Property::Scale,
            Interpolation::Step,
            &[0.0, 1.0],
            &[1.0, 1.0, 1.0, 2.0, 2.0, 2.0],
        );
        assert_eq!(step.sample(0.99), [1.0; 3]);
        assert_eq!(step.sample(1.0), [2.0; 3]);
        let quarter = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
        let turn = channel(
            Property::Rotation,
            Interpolation::Linear,
            &[0.0, 1.0],
            &[Quat::IDENTITY.to_array(), quarter.to_array()].concat(),
        );
        let half = Quat::from_slice(&turn.sample(0.5));
        assert!(
            half.abs_diff_eq(Quat::from_rotation_y(std::f32::consts::FRAC_PI_4), 1e-6),
            "{half}"
        );
        // A spline from 0 to 0 over 2 s leaving with slope 1: the Hermite basis at s = ½ gives
        // h10·Δt·b₀ = ⅛·2·1 = ¼.
        let spline = channel(
            Property::Translation,
            Interpolation::CubicSpline,
            &[0.0, 2.0],
            &[
                0.0, 0.0, 0.0, /* key 0: in */ 0.0, 0.0, 0.0, /* value */ 1.0, 0.0,
                0.0, /* out */
                0.0, 0.0, 0.0, /* key 1: in */ 0.0, 0.0, 0.0, /* value */ 0.0, 0.0,
                0.0, /* out */
            ],
        );
        assert_eq!(spline.sample(1.0), [0.25, 0.0, 0.0]);
        assert_eq!(spline.sample(2.0), [0.0, 0.0, 0.0]);
        let animation = Animation {
            name: "a".into(),
            channels: vec![slide, turn],
        };
        let nodes = [node(1, None, 0..0)];
        let [(1, local)] = animation.locals_at(&nodes, 2.0)[..] else {
            panic!("one node moved")
        };
        assert_eq!(local.translation, Vec3::new(2.0, 1.0, -1.0));
        assert!(local.rotation.abs_diff_eq(quarter, 1e-6));
        assert_eq!(local.scale, Vec3::ONE, "the node's own");
    }

    /// `render.nodes` entries override an animation for their nodes, one that gives the node's
    /// own pose too (it pins the node at rest); without an animation that moves nothing.
    #[test]
    fn explicit_poses_override_an_animation_even_at_rest() {
        let mut nodes = vec![
            node(0, None, 0..9),
            node(1, Some(0), 3..6),
            node(2, Some(0), 6..9),
        ];
        nodes[0].movable = false;
        let bounds = vec![None; 3];
        let room = Aabb {
            min: Vec3::splat(-10.0),
            max: Vec3::splat(10.0),
        };
        let back = resolve_poses(&nodes, &bounds, &room, &[pose(1)]).expect("valid");
        assert_eq!(
            back,
            Poses::new(),
            "an entry without fields puts its node back"
        );
        let own = lightcast_protocol::NodePose {
            translation: Some([0.0; 3]),
            rotation: Some([0.0, 0.0, 0.0, 1.0]),
            ..pose(1)
        };
        let pin = resolve_poses(&nodes, &bounds, &room, &[own]).expect("valid");
        assert_eq!(pin, vec![(1, Transform::IDENTITY)]);
        assert_eq!(merge_poses(&nodes, Vec::new(), &pin), Poses::new());
        let slid = |x: f32| Transform {
            translation: Vec3::X * x,
            ..Transform::IDENTITY
        };
        let animated = vec![(1, slid(1.0)), (2, slid(2.0))];
        assert_eq!(
            merge_poses(&nodes, animated.clone(), &pin),
            vec![(2, slid(2.0))]
        );
        let moved = resolve_poses(
            &nodes,
            &bounds,
            &room,
            &[lightcast_protocol::NodePose {
                translation: Some([3.0, 0.0, 0.0]),
                ..pose(2)
            }],
        )
        .expect("valid");
        assert_eq!(
            merge_poses(&nodes, animated, &moved),
            vec![(1, slid(1.0)), (2, slid(3.0))]
        );
    }

    /// A light carried by a moved node goes where the node takes it; one of an unmoved node,
    /// or of the scene as a whole, stays bit for bit.
    #[test]
    fn lights_of_moved_nodes_move_with_them() {
        let mut nodes = vec![
            node(0, None, 0..9),
            node(1, Some(0), 3..6),
            node(2, Some(0), 6..9),
        ];
        nodes[0].movable = false;
        let spot = lightcast_protocol::Light {
            kind: lightcast_protocol::LightKind::Spot,
            position: [1.0, 2.0, 0.0],
            direction: [0.0, 0.0, -1.0],
            color: [1.0; 3],
            intensity: 5.0,
            inner_cone: 0.2,
            outer_cone: 0.4,
        };
        let lights = vec![spot.clone(), spot.clone(), spot.clone()];
        let carried = [Some(1), Some(2), None];
        let turn = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
        let poses = vec![(
            1,
            Transform {
                translation: Vec3::new(0.0, 0.0, 3.0),
                rotation: turn,
                scale: Vec3::ONE,
            },
        )];
        let moved = posed_lights(&nodes, &lights, &carried, &poses);
        // Node 1 was at the origin unturned: p → t + q·p, d → q·d.
        let want_p = Vec3::new(0.0, 0.0, 3.0) + turn * Vec3::new(1.0, 2.0, 0.0);
        assert!(
            Vec3::from(moved[0].position).abs_diff_eq(want_p, 1e-6),
            "{:?}",
            moved[0]
        );
        let want_d = turn * Vec3::NEG_Z;
        assert!(
            Vec3::from(moved[0].direction).abs_diff_eq(want_d, 1e-6),
            "{:?}",
            moved[0]
        );
        assert_eq!(
            (moved[0].intensity, moved[0].kind),
            (spot.intensity, spot.kind)
        );
        assert_eq!(moved[1], spot, "node 2 stays");
        assert_eq!(moved[2], spot, "the scene's own light");
        assert_eq!(
            posed_lights(&nodes, &lights, &carried, &Poses::new()),
            lights
        );
    }

    #[test]
    fn transforms_round_trip_through_matrices() {
        let t = Transform {
            translation: Vec3::new(1.0, -2.0, 3.0),
            rotation: Quat::from_rotation_y(0.7) * Quat::from_rotation_x(0.2),
            scale: Vec3::new(2.0, 0.5, 1.5),
        };
        let back = Transform::from_matrix(&t.matrix()).expect("a TRS matrix");
        assert!(back.matrix().abs_diff_eq(t.matrix(), 1e-5));
        // A shear is no TRS.
        let shear = Mat4::from_cols_array(&[
            1.0, 0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ]);
        assert_eq!(Transform::from_matrix(&shear), None);
    }

    #[test]
    fn nested_ranges_pass_and_every_violation_is_named() {
        // Vertices 0..3 of the root, 3..6 of child 1, 6..9 of child 2 (under 1).
        let nodes = vec![
            node(0, None, 0..9),
            node(1, Some(0), 3..9),
            node(2, Some(1), 6..9),
        ];
        let tris = [0, 1, 2, 3, 4, 5, 6, 7, 8];
        assert_eq!(validate(&nodes, &[], 9, &tris), Ok(()));
        assert_eq!(
            validate(&nodes, &[], 9, &[0, 1, 3]),
            Err(NodeError::Straddles(0))
        );
        let outside = vec![node(0, None, 0..4), node(1, Some(0), 3..9)];
        assert!(matches!(
            validate(&outside, &[], 9, &[]),
            Err(NodeError::Vertices { node: 1, .. })
        ));
        let orphan = vec![node(1, Some(0), 0..3)];
        assert_eq!(
            validate(&orphan, &[], 9, &[]),
            Err(NodeError::Parent { node: 1, parent: 0 })
        );
        let twice = vec![node(0, None, 0..3), node(0, None, 3..6)];
        assert_eq!(
            validate(&twice, &[], 9, &[]),
            Err(NodeError::DuplicateId(0))
        );
        let animation = Animation {
            name: "spin".into(),
            channels: vec![Channel {
                node: 7,
                property: Property::Rotation,
                interpolation: Interpolation::Linear,
                times: vec![0.0, 2.5],
                values: vec![0.0; 8],
            }],
        };
        assert_eq!(animation.duration(), 2.5);
        assert_eq!(animation.channels[0].width(), 4);
        assert_eq!(
            validate(&nodes, &[animation], 9, &tris),
            Err(NodeError::Target {
                animation: "spin".into(),
                node: 7
            })
        );
    }
}
