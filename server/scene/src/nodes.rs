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
    /// Whether clients may move it (with its subtree): a procedural scene's movable parts,
    /// and in a glTF file every node an animation targets or whose `extras` say
    /// `"movable": true`, with their descendants.
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

/// Each vertex's innermost node (its position in `nodes`; `u32::MAX` for none), for nodes
/// [`validate`] accepts: one sweep over the vertices with a stack of the open ranges, so a
/// deep hierarchy costs no more than a flat one.
fn owners(nodes: &[Node], vertex_count: u32) -> Vec<u32> {
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
