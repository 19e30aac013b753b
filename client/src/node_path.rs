//! A node path (`stream --node-path`): movable nodes' poses at keyframe times, replayed as
//! `nodes` messages on the camera path's ticks.
//!
//! ```json
//! {"keyframes": [
//!   {"t": 0, "nodes": [{"node": 1, "translation": [0.33, 0, 0.37]}]},
//!   {"t": 2, "nodes": [{"node": 1, "translation": [0.13, 0, 0.37], "rotation": [0, 0.38268343, 0, 0.9238795]}]}]}
//! ```
//!
//! Each field of each node (translation, rotation, scale) is its own track through the
//! keyframes that give it: translation and scale interpolate linearly, rotation by spherical
//! linear interpolation (slerp), each held before its first keyframe and after its last. A
//! field no keyframe gives is left out of the messages, so the node keeps its own.

use crate::drive::{check_times, lerp3, read_json, sample};
use lightcast_protocol::NodePose;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

/// The file as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    keyframes: Vec<FileKeyframe>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileKeyframe {
    /// Seconds from the start.
    t: f64,
    nodes: Vec<NodePose>,
}

/// One field of one node: (seconds, value) in rising time.
type Track<T> = Vec<(f64, T)>;

#[derive(Clone, Debug, Default, PartialEq)]
struct NodeTracks {
    translation: Track<[f32; 3]>,
    /// Unit quaternions `[x, y, z, w]`.
    rotation: Track<[f32; 4]>,
    scale: Track<[f32; 3]>,
}

/// The server's bounds on a scale's components (`NodePose::scale`).
const SCALE_RANGE: std::ops::RangeInclusive<f32> = 1e-3..=1e3;

/// A loaded, checked node path.
#[derive(Clone, Debug, PartialEq)]
pub struct NodePath {
    nodes: BTreeMap<u32, NodeTracks>,
}

impl NodePath {
    /// Reads and checks `path`; an error names the file and what in it is wrong.
    pub fn load(path: &Path) -> Result<Self, String> {
        let file: File = read_json(path)?;
        Self::from_file(file).map_err(|e| format!("{}: {e}", path.display()))
    }

    fn from_file(file: File) -> Result<Self, String> {
        let times: Vec<f64> = file.keyframes.iter().map(|k| k.t).collect();
        check_times(&times)?;
        let mut nodes: BTreeMap<u32, NodeTracks> = BTreeMap::new();
        for (i, key) in file.keyframes.into_iter().enumerate() {
            if key.nodes.is_empty() {
                return Err(format!("keyframes[{i}] (t = {}) poses no node", key.t));
            }
            for (j, pose) in key.nodes.iter().enumerate() {
                let at = format!(
                    "keyframes[{i}].nodes[{j}] (node {}, t = {})",
                    pose.node, key.t
                );
                if let Some(first) = key.nodes[..j].iter().position(|p| p.node == pose.node) {
                    return Err(format!(
                        "{at}: the keyframe poses node {} twice (also nodes[{first}])",
                        pose.node
                    ));
                }
                if pose.translation.is_none() && pose.rotation.is_none() && pose.scale.is_none() {
                    return Err(format!("{at}: gives none of translation, rotation, scale"));
                }
                let tracks = nodes.entry(pose.node).or_default();
                if let Some(v) = pose.translation {
                    finite(&at, "translation", &v)?;
                    tracks.translation.push((key.t, v));
                }
                if let Some(q) = pose.rotation {
                    finite(&at, "rotation", &q)?;
                    let q = normalized(q).ok_or_else(|| {
                        format!("{at}: rotation {q:?} is a zero-length quaternion (give [x, y, z, w] of a rotation, e.g. [0, 0, 0, 1] for none)")
                    })?;
                    tracks.rotation.push((key.t, q));
                }
                if let Some(v) = pose.scale {
                    finite(&at, "scale", &v)?;
                    if !v.iter().all(|c| SCALE_RANGE.contains(c)) {
                        return Err(format!(
                            "{at}: scale {v:?} has a component outside [{}, {}]",
                            SCALE_RANGE.start(),
                            SCALE_RANGE.end()
                        ));
                    }
                    tracks.scale.push((key.t, v));
                }
            }
        }
        Ok(Self { nodes })
    }

    /// The ids of the nodes the path poses, in rising order.
    pub fn node_ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.nodes.keys().copied()
    }

    /// Every posed node at `t` seconds, one entry each (in rising id), with the fields its
    /// keyframes give.
    pub fn at(&self, t: f64) -> Vec<NodePose> {
        fn track<T: Copy>(keys: &Track<T>, t: f64, mix: impl Fn(T, T, f32) -> T) -> Option<T> {
            (!keys.is_empty())
                .then(|| sample(keys, t, |k| k.0, |k| k.1, |a, b, s| mix(a.1, b.1, s)))
        }
        self.nodes
            .iter()
            .map(|(&node, tracks)| NodePose {
                node,
                translation: track(&tracks.translation, t, lerp3),
                rotation: track(&tracks.rotation, t, slerp),
                scale: track(&tracks.scale, t, lerp3),
            })
            .collect()
    }
}

fn finite(at: &str, field: &str, values: &[f32]) -> Result<(), String> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(format!(
            "{at}: {field} {values:?} is not all finite numbers"
        ))
    }
}

/// `q` scaled to unit length; `None` when it has (next to) none.
fn normalized(q: [f32; 4]) -> Option<[f32; 4]> {
    let len = q.iter().map(|c| f64::from(*c).powi(2)).sum::<f64>().sqrt();
    (len > 1e-6).then(|| q.map(|c| (f64::from(c) / len) as f32))
}

/// Spherical linear interpolation of unit quaternions `a` → `b` at `s`, the shorter way round
/// (`q` and `−q` are the same rotation): a constant angular speed between keyframes, which a
/// normalised lerp only approximates (it speeds up in the middle of wide turns).
fn slerp(a: [f32; 4], b: [f32; 4], s: f32) -> [f32; 4] {
    let a = a.map(f64::from);
    let mut b = b.map(f64::from);
    let s = f64::from(s);
    let mut dot: f64 = (0..4).map(|i| a[i] * b[i]).sum();
    if dot < 0.0 {
        b = b.map(|c| -c);
        dot = -dot;
    }
    let (wa, wb) = if dot > 0.9995 {
        // Nearly the same rotation: sin θ ≈ 0 would divide by next to nothing, and a lerp is
        // as good there.
        (1.0 - s, s)
    } else {
        let theta = dot.acos();
        let sin = theta.sin();
        (((1.0 - s) * theta).sin() / sin, (s * theta).sin() / sin)
    };
    let q = [0, 1, 2, 3].map(|i| (wa * a[i] + wb * b[i]) as f32);
    normalized(q).unwrap_or(q)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<NodePath, String> {
        NodePath::from_file(serde_json::from_str(text).map_err(|e| e.to_string())?)
    }

    fn close<const N: usize>(a: [f32; N], b: [f32; N]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6)
    }

    /// A rotation of `degrees` about +Y.
    fn yaw(degrees: f32) -> [f32; 4] {
        let (s, c) = (degrees.to_radians() / 2.0).sin_cos();
        [0.0, s, 0.0, c]
    }

    #[test]
    fn translation_and_scale_interpolate_linearly_and_hold_at_the_ends() {
        let path = parse(
            r#"{"keyframes": [
                {"t": 1, "nodes": [{"node": 1, "translation": [0, 0, 0.2], "scale": [1, 1, 1]}]},
                {"t": 3, "nodes": [{"node": 1, "translation": [0.4, 0, -0.2], "scale": [2, 1, 0.5]}]}]}"#,
        )
        .expect("parses");
        let mid = &path.at(2.0)[0];
        assert_eq!(mid.node, 1);
        assert!(close(mid.translation.unwrap(), [0.2, 0.0, 0.0]), "{mid:?}");
        assert!(close(mid.scale.unwrap(), [1.5, 1.0, 0.75]), "{mid:?}");
        assert_eq!(
            mid.rotation, None,
            "no keyframe gives one: the node keeps its own"
        );
        let before = &path.at(0.0)[0];
        assert_eq!(before.translation, Some([0.0, 0.0, 0.2]));
        assert_eq!(before.scale, Some([1.0, 1.0, 1.0]));
        let after = &path.at(10.0)[0];
        assert_eq!(after.translation, Some([0.4, 0.0, -0.2]));
        assert_eq!(after.scale, Some([2.0, 1.0, 0.5]));
    }

    #[test]
    fn rotation_slerps_a_quarter_turn_to_an_eighth_at_the_midpoint() {
        let path = NodePath::from_file(File {
            keyframes: vec![
                FileKeyframe {
                    t: 0.0,
                    nodes: vec![pose(2, None, Some(yaw(0.0)))],
                },
                FileKeyframe {
                    t: 2.0,
                    nodes: vec![pose(2, None, Some(yaw(90.0)))],
                },
            ],
        })
        .expect("valid");
        let q = path.at(1.0)[0].rotation.unwrap();
        assert!(close(q, yaw(45.0)), "{q:?} against {:?}", yaw(45.0));
        // A quarter of the way is a quarter of the angle (slerp's constant speed).
        let q = path.at(0.5)[0].rotation.unwrap();
        assert!(close(q, yaw(22.5)), "{q:?}");
        assert!(close(path.at(-1.0)[0].rotation.unwrap(), yaw(0.0)));
        assert!(close(path.at(5.0)[0].rotation.unwrap(), yaw(90.0)));
    }

    #[test]
    fn slerp_goes_the_short_way_and_rotations_are_normalised() {
        // −q is q's rotation: from yaw 0 to −(yaw 90) is still a quarter turn, not three.
        let far = yaw(90.0).map(|c| -c);
        let q = slerp(yaw(0.0), far, 0.5);
        assert!(close(q, yaw(45.0)), "{q:?}");
        let path =
            parse(r#"{"keyframes": [{"t": 0, "nodes": [{"node": 1, "rotation": [0, 0, 0, 2]}]}]}"#)
                .expect("parses");
        assert_eq!(path.at(0.0)[0].rotation, Some([0.0, 0.0, 0.0, 1.0]));
    }

    #[test]
    fn each_node_follows_only_the_keyframes_that_pose_it() {
        let path = parse(
            r#"{"keyframes": [
                {"t": 0, "nodes": [{"node": 1, "translation": [0, 0, 0]}, {"node": 2, "translation": [1, 0, 0]}]},
                {"t": 1, "nodes": [{"node": 1, "translation": [1, 0, 0]}]},
                {"t": 4, "nodes": [{"node": 2, "translation": [0, 0, 0]}, {"node": 1, "translation": [1, 0, 1]}]}]}"#,
        )
        .expect("parses");
        assert_eq!(path.node_ids().collect::<Vec<_>>(), [1, 2]);
        let poses = path.at(2.0);
        // Node 1: a third of the way from t = 1 to t = 4.
        assert_eq!(poses[0].node, 1);
        assert!(close(poses[0].translation.unwrap(), [1.0, 0.0, 1.0 / 3.0]));
        // Node 2: half-way from t = 0 to t = 4 (the keyframe at t = 1 does not name it).
        assert_eq!(poses[1].node, 2);
        assert!(close(poses[1].translation.unwrap(), [0.5, 0.0, 0.0]));
        assert_eq!(path.at(0.5)[1].translation, Some([0.875, 0.0, 0.0]));
    }

    fn pose(node: u32, translation: Option<[f32; 3]>, rotation: Option<[f32; 4]>) -> NodePose {
        NodePose {
            node,
            translation,
            rotation,
            scale: None,
        }
    }

    fn refused(file: File) -> String {
        NodePath::from_file(file).expect_err("refused")
    }

    #[test]
    fn bad_files_are_refused_saying_where_and_why() {
        let one = |t: f64, nodes: Vec<NodePose>| FileKeyframe { t, nodes };
        let e = refused(File { keyframes: vec![] });
        assert_eq!(e, "no keyframes");
        let e = refused(File {
            keyframes: vec![
                one(0.0, vec![pose(1, Some([0.0; 3]), None)]),
                one(2.0, vec![pose(1, Some([0.0; 3]), None)]),
                one(2.0, vec![pose(1, Some([0.0; 3]), None)]),
            ],
        });
        assert!(
            e.contains("must rise") && e.contains("keyframes[2].t = 2"),
            "{e}"
        );
        let e = refused(File {
            keyframes: vec![one(f64::NAN, vec![pose(1, Some([0.0; 3]), None)])],
        });
        assert!(e.contains("keyframes[0].t is not a finite number"), "{e}");
        let e = refused(File {
            keyframes: vec![
                one(0.0, vec![pose(1, Some([0.0; 3]), None)]),
                one(
                    1.0,
                    vec![
                        pose(2, None, None),
                        pose(1, Some([f32::NAN, 0.0, 0.0]), None),
                    ],
                ),
            ],
        });
        assert!(
            e.starts_with("keyframes[1].nodes[0] (node 2, t = 1): gives none"),
            "{e}"
        );
        let e = refused(File {
            keyframes: vec![one(0.0, vec![pose(1, Some([f32::NAN, 0.0, 0.0]), None)])],
        });
        assert!(
            e.starts_with("keyframes[0].nodes[0] (node 1, t = 0): translation [NaN, 0.0, 0.0]"),
            "{e}"
        );
        let e = refused(File {
            keyframes: vec![one(0.0, vec![pose(1, None, Some([0.0; 4]))])],
        });
        assert!(
            e.contains("(node 1, t = 0): rotation") && e.contains("zero-length quaternion"),
            "{e}"
        );
        let e = refused(File {
            keyframes: vec![one(
                0.0,
                vec![pose(1, None, Some([0.0, f32::INFINITY, 0.0, 1.0]))],
            )],
        });
        assert!(
            e.contains("rotation") && e.contains("not all finite"),
            "{e}"
        );
        let e = refused(File {
            keyframes: vec![one(
                0.0,
                vec![NodePose {
                    scale: Some([1.0, 0.0, 1.0]),
                    ..pose(1, None, None)
                }],
            )],
        });
        assert!(
            e.contains("scale [1.0, 0.0, 1.0] has a component outside"),
            "{e}"
        );
        let e = refused(File {
            keyframes: vec![one(0.0, vec![])],
        });
        assert_eq!(e, "keyframes[0] (t = 0) poses no node");
        let e = refused(File {
            keyframes: vec![one(
                0.0,
                vec![pose(1, Some([0.0; 3]), None), pose(1, None, Some(yaw(0.0)))],
            )],
        });
        assert!(
            e.contains("nodes[1] (node 1, t = 0): the keyframe poses node 1 twice (also nodes[0])"),
            "{e}"
        );
    }

    #[test]
    fn the_file_is_read_strictly_and_named_in_errors() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join("boxes.json");
        let write = |text: &str| std::fs::write(&file, text).expect("write");
        write(r#"{"keyframes": []}"#);
        let e = NodePath::load(&file).expect_err("refused");
        assert!(
            e.starts_with(&file.display().to_string()) && e.ends_with(": no keyframes"),
            "{e}"
        );
        // A misspelt field is named, not ignored; so is a number too large for an f32.
        write(r#"{"keyframes": [{"t": 0, "nodes": [{"node": 1, "translaton": [0, 0, 0]}]}]}"#);
        let e = NodePath::load(&file).expect_err("refused");
        assert!(e.contains("boxes.json") && e.contains("translaton"), "{e}");
        write(r#"{"keyframes": [{"t": 0, "nodes": [{"node": 1, "translation": [1e39, 0, 0]}]}]}"#);
        let e = NodePath::load(&file).expect_err("refused");
        assert!(e.contains("boxes.json") && e.contains("translation"), "{e}");
        let e = NodePath::load(&dir.path().join("missing.json")).expect_err("refused");
        assert!(e.contains("missing.json"), "{e}");
    }
}
