//! The frame's environment on the GPU (`shaders/environment.wgsl`): one read-only storage
//! buffer of f32 words that the direct-light pass (the sky behind the geometry) and the
//! reference (importance-sampled sky light) bind as `environment`.

use crate::scene::environment::{EnvironmentError, EnvironmentMap, EnvironmentSampling};
use crate::scene::environment_image::EnvironmentImage;
use lightcast_protocol::{Environment, Light};

/// A frame's environment, evaluated: its map, what samples it, the words the shaders read
/// and the directional lights a real-time method lights with instead.
#[derive(Debug)]
pub struct FrameEnvironment {
    pub map: EnvironmentMap,
    pub sampling: EnvironmentSampling,
    /// [`pack`]ed map and tables.
    pub words: Vec<f32>,
    /// `directions` lights of about equal power (median cut; see
    /// [`EnvironmentMap::median_cut`]).
    pub lights: Vec<Light>,
}

impl FrameEnvironment {
    /// `env` for a frame whose punctual lights are `lights` (a sky's sun is among them), of a
    /// scene whose environment image is `image`.
    pub fn new(
        env: &Environment,
        lights: &[Light],
        image: Option<&EnvironmentImage>,
    ) -> Result<Self, EnvironmentError> {
        let map = EnvironmentMap::new(env, lights, image)?;
        let sampling = map.sampling();
        let words = pack(Some((&map, &sampling)));
        let lights = map.median_cut(env.directions as usize);
        Ok(Self {
            map,
            sampling,
            words,
            lights,
        })
    }
}

/// Two frames see the same environment when their maps are equal.
impl PartialEq for FrameEnvironment {
    fn eq(&self, other: &Self) -> bool {
        self.map == other.map
    }
}

/// Words before the texels: width and height (as u32 bits), two unused.
const HEADER: usize = 4;

/// The words `shaders/environment.wgsl` reads for `map` with its sampling tables; the header
/// alone (0 × 0) for none.
pub fn pack(map: Option<(&EnvironmentMap, &EnvironmentSampling)>) -> Vec<f32> {
    let Some((map, sampling)) = map else {
        return vec![0.0; HEADER];
    };
    let texels = map.radiance.len();
    let mut words = Vec::with_capacity(HEADER + 5 * texels + sampling.rows.len());
    words.extend([
        f32::from_bits(map.width),
        f32::from_bits(map.height),
        0.0,
        0.0,
    ]);
    for (rgb, pdf) in map.radiance.iter().zip(&sampling.pdf) {
        words.extend([rgb[0], rgb[1], rgb[2], *pdf]);
    }
    words.extend(&sampling.rows);
    words.extend(&sampling.columns);
    words
}

/// A storage buffer holding packed environment words, re-created when their length changes.
pub struct EnvironmentBuffer {
    pub buffer: wgpu::Buffer,
    words: Vec<f32>,
}

impl EnvironmentBuffer {
    /// A buffer holding no environment.
    pub fn new(device: &wgpu::Device) -> Self {
        let words = pack(None);
        Self {
            buffer: Self::create(device, words.len()),
            words,
        }
    }

    fn create(device: &wgpu::Device, len: usize) -> wgpu::Buffer {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("environment"),
            size: (len * 4) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Holds `env` (none: no environment) from the next submission on; writes nothing when
    /// it is what it holds. Returns whether the buffer was re-created (bind groups holding
    /// the old one must be re-made).
    pub fn set(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        env: Option<&FrameEnvironment>,
    ) -> bool {
        let none;
        let words = match env {
            Some(e) => &e.words,
            None => {
                none = pack(None);
                &none
            }
        };
        if *words == self.words {
            return false;
        }
        let recreated = words.len() != self.words.len();
        if recreated {
            self.buffer = Self::create(device, words.len());
        }
        queue.write_buffer(&self.buffer, 0, bytemuck::cast_slice(words));
        self.words = words.clone();
        recreated
    }
}
