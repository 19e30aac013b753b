//! The scene graph and its meshes: nodes from the roots down with their transforms,
//! primitives as world-space triangles (topologies, degenerate triangles, normals), counted
//! against the triangle budget.

use super::*;

/// Converts a triangle list, strip or fan into a list (spec §3.7.2.1 orderings).
pub(super) fn triangle_list(mode: Mode, indices: &[u32]) -> Result<Vec<[u32; 3]>, String> {
    match mode {
        Mode::Triangles if !indices.len().is_multiple_of(3) => Err(format!(
            "index count {} is not a multiple of 3",
            indices.len()
        )),
        Mode::Triangles => Ok(indices
            .chunks_exact(3)
            .filter_map(|t| <[u32; 3]>::try_from(t).ok())
            .collect()),
        Mode::TriangleStrip => Ok(indices
            .windows(3)
            .enumerate()
            .filter_map(|(i, w)| match *w {
                [a, b, c] if i % 2 == 0 => Some([a, b, c]),
                [a, b, c] => Some([a, c, b]),
                _ => None,
            })
            .collect()),
        Mode::TriangleFan => {
            let (Some(&first), Some(rest)) = (indices.first(), indices.get(1..)) else {
                return Ok(Vec::new());
            };
            Ok(rest
                .windows(2)
                .filter_map(|w| match *w {
                    [b, c] => Some([b, c, first]),
                    _ => None,
                })
                .collect())
        }
        other => Err(format!("mode {other:?} is not supported (only triangles)")),
    }
}

/// Area-weighted vertex normals (the cross product's length is twice the triangle area).
/// Whether a triangle covers any area (distinct corners that are not collinear).
pub(super) fn has_area(positions: &[Vec3], t: &[u32; 3]) -> bool {
    let [a, b, c] = t.map(|i| positions[i as usize].as_dvec3());
    (b - a).cross(c - a).length_squared() > 0.0
}

/// The vertices of `count` that `triangles` use, in their order (a file without unused
/// vertices keeps its numbering), and the triangles renumbered to index that list.
pub(super) fn compact(count: usize, triangles: &[[u32; 3]]) -> (Vec<u32>, Vec<[u32; 3]>) {
    let mut new_index = vec![u32::MAX; count];
    for &i in triangles.iter().flatten() {
        new_index[i as usize] = 0;
    }
    let mut kept = Vec::new();
    for (old, slot) in new_index.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = kept.len() as u32;
            kept.push(old as u32);
        }
    }
    let renumbered = triangles
        .iter()
        .map(|t| t.map(|i| new_index[i as usize]))
        .collect();
    (kept, renumbered)
}

pub(super) fn generated_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut sums = vec![Vec3::ZERO; positions.len()];
    for triangle in triangles {
        let [a, b, c] = triangle.map(|i| positions.get(i as usize).copied().unwrap_or(Vec3::ZERO));
        let normal = (b - a).cross(c - a);
        for &i in triangle {
            if let Some(sum) = sums.get_mut(i as usize) {
                *sum += normal;
            }
        }
    }
    sums.into_iter()
        .map(|n| n.try_normalize().unwrap_or(Vec3::Y))
        .collect()
}

/// A node's authored translation, rotation (normalised; identity if degenerate, as
/// [`local_transform`] refuses it first) and scale.
pub(super) fn local_trs(node: &json::Node) -> Transform {
    Transform {
        translation: node.translation.map_or(Vec3::ZERO, Vec3::from),
        rotation: node
            .rotation
            .as_ref()
            .map(|q| Quat::from_array(q.0))
            .filter(|q| q.is_finite() && q.length_squared() > 0.0)
            .map_or(Quat::IDENTITY, Quat::normalize),
        scale: node.scale.map_or(Vec3::ONE, Vec3::from),
    }
}

pub(super) fn local_transform(node: &json::Node) -> Option<Mat4> {
    if let Some(matrix) = node.matrix {
        return Some(Mat4::from_cols_array(&matrix));
    }
    let translation = node.translation.map_or(Vec3::ZERO, Vec3::from);
    let scale = node.scale.map_or(Vec3::ONE, Vec3::from);
    let rotation = match &node.rotation {
        None => Quat::IDENTITY,
        Some(q) => {
            let q = Quat::from_array(q.0);
            if !q.is_finite() || q.length_squared() == 0.0 {
                return None;
            }
            q.normalize()
        }
    };
    Some(Mat4::from_scale_rotation_translation(
        scale,
        rotation,
        translation,
    ))
}

impl Loader<'_> {
    /// Root nodes of the default scene, else scene 0, else every node that is nobody's child.
    pub(super) fn root_nodes(&self) -> Result<Vec<usize>, LoadError> {
        let root = self.root;
        let scene = root
            .scene
            .map(|s| s.value())
            .or_else(|| (!root.scenes.is_empty()).then_some(0));
        if let Some(index) = scene {
            let scene = root
                .scenes
                .get(index)
                .ok_or_else(|| invalid(format!("scene {index}"), "does not exist"))?;
            return Ok(scene.nodes.iter().map(|n| n.value()).collect());
        }
        let mut is_child = vec![false; root.nodes.len()];
        for child in root.nodes.iter().flat_map(|n| n.children.iter().flatten()) {
            if let Some(flag) = is_child.get_mut(child.value()) {
                *flag = true;
            }
        }
        Ok(is_child
            .iter()
            .enumerate()
            .filter(|(_, &child)| !child)
            .map(|(i, _)| i)
            .collect())
    }

    /// Walks the hierarchy depth first, adding each node's mesh, camera and light in world
    /// space, and returns the nodes in that (pre)order with their subtrees' vertex ranges;
    /// `moving[i]` says glTF node `i` is animated.
    pub(super) fn traverse(&mut self, moving: &[bool]) -> Result<Vec<Node>, LoadError> {
        let root = self.root;
        let mut visited = vec![false; root.nodes.len()];
        let mut nodes: Vec<Node> = Vec::new();
        // (glTF index, parent's world transform, parent's position in `nodes`)
        let mut stack: Vec<(usize, Mat4, Option<usize>)> = self
            .root_nodes()?
            .into_iter()
            .rev()
            .map(|n| (n, Mat4::IDENTITY, None))
            .collect();
        while let Some((index, parent, up)) = stack.pop() {
            let node = root
                .nodes
                .get(index)
                .ok_or_else(|| invalid(format!("node {index}"), "does not exist"))?;
            let part = named("node", index, node.name.as_deref());
            match visited.get_mut(index) {
                Some(seen) if !*seen => *seen = true,
                _ => {
                    return Err(invalid(
                        part,
                        "appears more than once in the node hierarchy (a cycle or a node with \
                         two parents)",
                    ))
                }
            }
            let local = local_transform(node)
                .filter(|local| (parent * *local).is_finite())
                .ok_or_else(|| invalid(&part, "transform is not finite"))?;
            let world = parent * local;
            // The authored translation, rotation and scale where there is no matrix (a
            // decomposition would move a negative scale's sign to another axis).
            let local = match node.matrix {
                Some(_) => Transform::from_matrix(&local),
                None => Some(local_trs(node)),
            };
            // Moved directly: an animation's translation, rotation or scale, or its extras.
            let moved = moving.get(index).copied().unwrap_or(false) || marked_movable(&node.extras);
            if moved && local.is_none() {
                return Err(invalid(
                    &part,
                    "moves (an animation targets it or it is marked movable), but its matrix \
                     is no translation, rotation and scale",
                ));
            }
            // Under a movable node it moves with it, and clients may pose it too where it has
            // a translation, rotation and scale to set.
            let movable = moved || (up.is_some_and(|p| nodes[p].movable) && local.is_some());
            let start = self.vertices.len() as u32;
            if let Some(mesh) = node.mesh {
                self.add_mesh(mesh.value(), &world)?;
            }
            if let Some(camera) = node.camera {
                self.add_camera(camera.value(), &world)?;
            }
            if let Some(light) = node
                .extensions
                .as_ref()
                .and_then(|e| e.khr_lights_punctual.as_ref())
            {
                self.add_light(light.light.value(), &world, &part)?;
                self.light_nodes.push(index as u32);
            }
            let position = nodes.len();
            nodes.push(Node {
                id: index as u32,
                name: node.name.clone().unwrap_or_default(),
                parent: up.map(|p| nodes[p].id),
                movable,
                local,
                rest_world: world,
                vertices: start..self.vertices.len() as u32,
            });
            for child in node.children.iter().flatten().rev() {
                stack.push((child.value(), world, Some(position)));
            }
        }
        // Preorder: a subtree's vertices end where its last descendant's do.
        let parents: Vec<Option<usize>> = {
            let at: std::collections::HashMap<u32, usize> =
                nodes.iter().enumerate().map(|(i, n)| (n.id, i)).collect();
            nodes
                .iter()
                .map(|n| n.parent.and_then(|p| at.get(&p).copied()))
                .collect()
        };
        for i in (0..nodes.len()).rev() {
            if let Some(p) = parents[i] {
                nodes[p].vertices.end = nodes[p].vertices.end.max(nodes[i].vertices.end);
            }
        }
        Ok(nodes)
    }

    pub(super) fn add_mesh(&mut self, index: usize, world: &Mat4) -> Result<(), LoadError> {
        let mesh = self
            .root
            .meshes
            .get(index)
            .ok_or_else(|| invalid(format!("mesh {index}"), "does not exist"))?;
        let mesh_part = named("mesh", index, mesh.name.as_deref());
        for (i, primitive) in mesh.primitives.iter().enumerate() {
            self.add_primitive(primitive, &format!("{mesh_part} primitive {i}"), world)?;
        }
        Ok(())
    }

    pub(super) fn add_primitive(
        &mut self,
        primitive: &json::mesh::Primitive,
        part: &str,
        world: &Mat4,
    ) -> Result<(), LoadError> {
        let Checked::Valid(mode) = primitive.mode else {
            return Err(invalid(part, "mode is invalid"));
        };
        // Checked before reading any data so that line and point primitives get this message.
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            return Err(invalid(
                part,
                format!("mode {mode:?} is not supported (only triangles)"),
            ));
        }
        let attribute = |semantic| {
            primitive
                .attributes
                .get(&Checked::Valid(semantic))
                .map(|a| a.value())
        };
        let position_accessor = attribute(Semantic::Positions)
            .ok_or_else(|| invalid(part, "has no POSITION attribute"))?;
        self.check_budget(
            mode,
            position_accessor,
            primitive.indices.map(|a| a.value()),
            part,
        )?;
        let positions = self.read_floats(position_accessor, Type::Vec3, part, "POSITION")?;
        let count = positions.len() / 3;
        let positions: Vec<Vec3> = positions.chunks_exact(3).map(Vec3::from_slice).collect();
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(invalid(part, format!("POSITION {i} is not finite")));
        }
        let normals = match attribute(Semantic::Normals) {
            Some(accessor) => {
                let normals = self.read_floats(accessor, Type::Vec3, part, "NORMAL")?;
                check_count(normals.len() / 3, count, part, "NORMAL")?;
                Some(
                    normals
                        .chunks_exact(3)
                        .map(Vec3::from_slice)
                        .collect::<Vec<_>>(),
                )
            }
            None => None,
        };
        let uvs = match attribute(Semantic::TexCoords(0)) {
            Some(accessor) => {
                let uvs = self.read_floats(accessor, Type::Vec2, part, "TEXCOORD_0")?;
                check_count(uvs.len() / 2, count, part, "TEXCOORD_0")?;
                uvs
            }
            None => vec![0.0; count * 2],
        };

        let indices = match primitive.indices {
            Some(accessor) => {
                let accessor = accessor.value();
                let indices = self.read_accessor(
                    accessor,
                    Type::Scalar,
                    INDEX_COMPONENTS,
                    part,
                    "indices",
                    |c, _, b| decode_index(c, b),
                )?;
                if let Some((position, index)) = indices
                    .iter()
                    .enumerate()
                    .find(|(_, &i)| i as usize >= count)
                {
                    return Err(invalid(
                        part,
                        format!(
                            "indices accessor {accessor}: index {index} at position {position} \
                             is out of range ({count} vertices)"
                        ),
                    ));
                }
                indices
            }
            None => {
                let count = u32::try_from(count)
                    .map_err(|_| invalid(part, format!("has too many vertices ({count})")))?;
                (0..count).collect()
            }
        };
        let mut triangles =
            triangle_list(mode, &indices).map_err(|message| invalid(part, message))?;

        let linear = Mat3::from_mat4(*world);
        // A mirroring transform turns counter-clockwise front faces clockwise.
        if linear.determinant() < 0.0 {
            for t in &mut triangles {
                t.swap(1, 2);
            }
        }
        let positions: Vec<Vec3> = positions
            .iter()
            .map(|&p| world.transform_point3(p))
            .collect();
        // Zero-area triangles light nothing and cover no pixel, but cost memory in every
        // buffer and light-cache step: a few hundred bytes of zero-filled accessors would
        // otherwise hold millions of them. Only the vertices the rest use are kept.
        triangles.retain(|t| has_area(&positions, t));
        let normals: Vec<Vec3> = match normals {
            Some(normals) => {
                let normal_matrix = linear.inverse().transpose();
                normals
                    .into_iter()
                    .map(|n| (normal_matrix * n).try_normalize().unwrap_or(Vec3::Y))
                    .collect()
            }
            None => generated_normals(&positions, &triangles),
        };
        let (kept, triangles) = compact(count, &triangles);

        let material = self.material_index(primitive.material.map(|m| m.value()))?;
        let base = self.vertices.len();
        if u32::try_from(base + kept.len()).is_err() {
            return Err(invalid(part, "scene would exceed 2^32 vertices"));
        }
        let base = base as u32;
        self.vertices.extend(kept.iter().map(|&i| {
            let i = i as usize;
            Vertex {
                position: positions[i].to_array(),
                normal: normals[i].to_array(),
                uv: [uvs[2 * i], uvs[2 * i + 1]],
                material,
            }
        }));
        self.indices
            .extend(triangles.iter().flatten().map(|&i| base + i));
        Ok(())
    }

    /// Refuses a primitive whose accessor counts alone would take the scene past its limits,
    /// before any of its data is read.
    pub(super) fn check_budget(
        &self,
        mode: Mode,
        positions: usize,
        indices: Option<usize>,
        part: &str,
    ) -> Result<(), LoadError> {
        let count = |accessor: usize| self.root.accessors.get(accessor).map_or(0, |a| a.count.0);
        let vertices = count(positions);
        let corners = indices.map_or(vertices, count);
        let triangles = match mode {
            Mode::Triangles => corners / 3,
            _ => corners.saturating_sub(2),
        };
        // Triangles first: the vertex limit follows from theirs, and a scene too large for
        // the triangle budget is told so.
        let total_triangles = (self.indices.len() as u64 / 3).saturating_add(triangles);
        if total_triangles > self.limits.max_triangles {
            return Err(LoadError::TriangleBudget {
                part: part.to_owned(),
                triangles: total_triangles,
                limit: self.limits.max_triangles,
            });
        }
        let total_vertices = (self.vertices.len() as u64).saturating_add(vertices);
        if total_vertices > self.limits.max_vertices {
            return Err(invalid(
                part,
                format!(
                    "the scene would have {total_vertices} vertices or more; at most {} are \
                     allowed",
                    self.limits.max_vertices
                ),
            ));
        }
        Ok(())
    }
}
