//! Light caches on the GPU: the caches, each vertex's 16 nearest caches, and the proxy
//! lights written every frame by cache lighting.

use super::caches::{CacheSet, LightCache, NEIGHBOURS, STATIC};
use crate::gi::lightskin::cache_lighting::{CacheAccum, CacheLighting};
use crate::scene::nodes::{posed_worlds, Node, Poses};
use wgpu::util::DeviceExt;

pub struct CacheBuffers {
    pub caches: wgpu::Buffer,
    pub vertex_caches: wgpu::Buffer,
    /// The proxy lights of frames that do not share them.
    pub lighting: wgpu::Buffer,
    /// The proxy lights of each input sessions share (`shared::MAX_SHARED_INPUTS`, made when
    /// first used: 64 bytes a cache each).
    shared_lighting: Vec<wgpu::Buffer>,
    /// Sums carried between the chunked cache-lighting dispatches.
    pub accum: wgpu::Buffer,
    /// Covered proxy areas carried between the chunked occlusion dispatches.
    pub coverage: wgpu::Buffer,
    /// Each cache's visibility map (`cache_visibility::CacheVisibility::distances`), or one
    /// unread texel without them.
    pub visibility: wgpu::Buffer,
    /// Their side; 0: none.
    pub visibility_side: u32,
    pub count: u32,
    /// The caches of movable models as the precomputation placed them (index, cache), and
    /// the poses `caches` holds them in.
    moving: Vec<(u32, LightCache)>,
    poses: Poses,
}

impl CacheBuffers {
    /// Makes lighting buffer `at` (see [`Self::lighting_at`]) if it is not yet.
    pub fn ensure_lighting(&mut self, device: &wgpu::Device, at: usize) {
        while self.shared_lighting.len() < at {
            self.shared_lighting
                .push(lighting_buffer(device, self.count as usize));
        }
    }

    /// Lighting buffer `at`: 0 holds the proxies of frames that do not share them, 1 onwards
    /// those of one shared input each (made by [`Self::ensure_lighting`]; 0's otherwise).
    pub fn lighting_at(&self, at: usize) -> &wgpu::Buffer {
        at.checked_sub(1)
            .and_then(|i| self.shared_lighting.get(i))
            .unwrap_or(&self.lighting)
    }

    pub fn new(device: &wgpu::Device, set: &CacheSet) -> Self {
        // Storage bindings may not be empty; a scene without caches binds one dummy cache that
        // no vertex refers to.
        let dummy = [<LightCache as bytemuck::Zeroable>::zeroed()];
        let caches: &[LightCache] = if set.caches.is_empty() {
            &dummy
        } else {
            &set.caches
        };
        let no_vertices = [[u32::MAX; NEIGHBOURS]];
        let vertex_caches: &[[u32; NEIGHBOURS]] = if set.vertex_caches.is_empty() {
            &no_vertices
        } else {
            &set.vertex_caches
        };
        let storage = wgpu::BufferUsages::STORAGE;
        Self {
            caches: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("light caches"),
                contents: bytemuck::cast_slice(caches),
                // Moving models' caches are written again where a frame poses them (and read
                // back by the test of that).
                usage: storage | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            }),
            vertex_caches: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("vertex caches"),
                contents: bytemuck::cast_slice(vertex_caches),
                usage: storage,
            }),
            lighting: lighting_buffer(device, caches.len()),
            shared_lighting: Vec::new(),
            accum: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("cache lighting sums"),
                size: (caches.len() * std::mem::size_of::<CacheAccum>()) as u64,
                usage: storage,
                mapped_at_creation: false,
            }),
            coverage: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("occlusion coverage"),
                size: (caches.len() * 8) as u64,
                usage: storage,
                mapped_at_creation: false,
            }),
            visibility: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("cache visibility"),
                contents: bytemuck::cast_slice(
                    set.visibility
                        .as_ref()
                        .map(|v| &v.distances[..])
                        .filter(|d| !d.is_empty())
                        .unwrap_or(&[0.0f32]),
                ),
                usage: storage,
            }),
            visibility_side: set.visibility.as_ref().map_or(0, |v| v.side),
            count: set.caches.len() as u32,
            moving: set
                .caches
                .iter()
                .enumerate()
                .filter(|(_, c)| c.model != STATIC)
                .map(|(i, c)| (i as u32, *c))
                .collect(),
            poses: Poses::new(),
        }
    }

    /// Places the moving models' caches by `poses` (seed 004 §3: a model's caches live in its
    /// space and move with it): position by the model's change from rest, normal by its
    /// inverse transpose; written where they changed.
    pub fn set_poses(&mut self, queue: &wgpu::Queue, nodes: &[Node], poses: &Poses) {
        if *poses == self.poses {
            return;
        }
        let worlds = posed_worlds(nodes, poses);
        let placed: Vec<(u32, LightCache)> = self
            .moving
            .iter()
            .map(|&(index, rest)| {
                // An unmoved model keeps its caches bit for bit (posed_worlds leaves its rest
                // transform as it is; renormalising a normal could change its last bit).
                let Some(node) = nodes
                    .get(rest.model as usize)
                    .filter(|n| worlds[rest.model as usize] != n.rest_world)
                else {
                    return (index, rest);
                };
                let delta = worlds[rest.model as usize] * node.rest_world.inverse();
                let normals = glam::Mat3::from_mat4(delta).inverse().transpose();
                let moved = LightCache {
                    position: delta.transform_point3(rest.position.into()).to_array(),
                    normal: (normals * glam::Vec3::from(rest.normal))
                        .try_normalize()
                        .unwrap_or(glam::Vec3::Y)
                        .to_array(),
                    ..rest
                };
                (index, moved)
            })
            .collect();
        // A model's caches are contiguous (the distribution goes model by model): one write
        // per run of consecutive indices.
        let size = std::mem::size_of::<LightCache>() as u64;
        for run in placed.chunk_by(|a, b| b.0 == a.0 + 1) {
            let caches: Vec<LightCache> = run.iter().map(|(_, c)| *c).collect();
            queue.write_buffer(
                &self.caches,
                u64::from(run[0].0) * size,
                bytemuck::cast_slice(&caches),
            );
        }
        self.poses = poses.clone();
    }
}

/// A buffer of `caches` proxy-light pairs.
fn lighting_buffer(device: &wgpu::Device, caches: usize) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("cache lighting"),
        size: (caches.max(1) * std::mem::size_of::<CacheLighting>()) as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}
