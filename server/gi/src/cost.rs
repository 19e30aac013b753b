//! What a frame or a precomputation will cost, estimated from its parameters before it runs,
//! so that the service can refuse a request that would hold the GPU (or the precompute
//! worker) for minutes up front, naming the parameter to lower (issue 30).
//!
//! A cost is in reference nanoseconds: the time the reference adapter, lavapipe on the 2-core
//! x86-64 VM this project is developed and tested on, takes for the work. Each method states
//! its own formula ([`super::MethodEntry::cost`]) as a sum of terms, each a count of the
//! method's work items (pixel·VPL pairs, rays, cache·VAL pairs, map texels) times the time
//! one item took there (the weights below; `bench/hostile-cost.sh` measures requests against
//! their estimates). An adapter's speed relative to the reference turns a cost into seconds
//! on that adapter; a GPU's is a configured ratio, not a measurement (the service's
//! `--adapter-speed`).

use super::common::params::{indirect_downscale, INDIRECT_DOWNSCALE, RSM_SIZE};
use super::params::Param;
use lightcast_protocol::GiParams;

/// One term of a cost: what is counted and its estimated reference nanoseconds.
#[derive(Clone, Debug, PartialEq)]
pub struct Term {
    /// The formula in words (`pixel·VPL shading (pixels × vpl_count / interleave²)`).
    pub what: &'static str,
    pub ns: f64,
}

/// An estimate: the sum of its terms.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Cost {
    terms: Vec<Term>,
}

impl Cost {
    /// Adds `count` items of `ns_each` reference nanoseconds.
    pub fn add(&mut self, what: &'static str, count: f64, ns_each: f64) {
        if count > 0.0 {
            self.terms.push(Term {
                what,
                ns: count * ns_each,
            });
        }
    }

    pub fn ns(&self) -> f64 {
        self.terms.iter().map(|t| t.ns).sum()
    }

    /// Estimated seconds on an adapter `speed` times as fast as the reference.
    pub fn seconds(&self, speed: f64) -> f64 {
        self.ns() * 1e-9 / speed
    }

    pub fn terms(&self) -> &[Term] {
        &self.terms
    }

    /// The largest terms with their share, for people: `pixel·VPL shading 81 %, k-means 12 %`.
    pub fn breakdown(&self) -> String {
        let total = self.ns().max(f64::MIN_POSITIVE);
        let mut terms: Vec<&Term> = self.terms.iter().collect();
        terms.sort_by(|a, b| b.ns.total_cmp(&a.ns));
        terms
            .iter()
            .take(3)
            .filter(|t| t.ns >= 0.005 * total)
            .map(|t| format!("{} {:.0} %", t.what, 100.0 * t.ns / total))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// What a frame's cost depends on besides its GI parameters.
#[derive(Clone, Copy, Debug)]
pub struct FrameShape {
    pub width: u32,
    pub height: u32,
    pub shadow_map_size: u32,
    /// Lights of the frame the method lights with: its punctual lights (and, after
    /// [`FrameShape::lit_by`], the environment's directions).
    pub lights: u32,
    /// Faces of all the lights' shadow maps and RSMs (6 per point light).
    pub light_faces: u32,
    /// The environment's directions (`None`: no environment; after [`FrameShape::lit_by`],
    /// only for a method that samples it itself).
    pub environment: Option<u32>,
    /// Faces a directional light renders from: 1, or 2 with its maps fitted to the view
    /// (`light_fit: view`'s cascades).
    pub directional_faces: u32,
    pub triangles: u64,
    /// Units of the precomputed set the frame reads (light caches; surfel links), estimated
    /// before it is built.
    pub set_units: u64,
    /// A multi-bounce method adds every bounce this frame (a one-shot render or a still), not
    /// the one a streamed frame adds.
    pub all_bounces: bool,
}

impl FrameShape {
    /// The shape as a method lights it: one that samples the environment itself (see
    /// `MethodEntry::samples_environment`) keeps it apart; any other lights with its
    /// directions as directional lights, [`FrameShape::directional_faces`] shadow-map faces
    /// each.
    pub fn lit_by(self, samples_environment: bool) -> Self {
        match self.environment {
            Some(d) if !samples_environment => Self {
                lights: self.lights + d,
                light_faces: self.light_faces + d * self.directional_faces,
                environment: None,
                ..self
            },
            _ => self,
        }
    }

    pub fn pixels(&self) -> f64 {
        f64::from(self.width) * f64::from(self.height)
    }

    /// The pixels a method that computes indirect light at `gi.indirect_downscale` shades.
    pub fn reduced_pixels(&self, gi: &GiParams) -> f64 {
        let d = indirect_downscale(gi).max(1);
        f64::from(self.width.div_ceil(d)) * f64::from(self.height.div_ceil(d))
    }

    /// Texels of an RSM of side `gi.rsm_size` over every light face.
    pub fn rsm_texels(&self, gi: &GiParams) -> f64 {
        f64::from(self.light_faces) * f64::from(RSM_SIZE.u32(gi)).powi(2)
    }
}

/// Reference ns to rasterise one triangle once (vertex work and set-up, lavapipe).
pub const NS_PER_TRIANGLE: f64 = 1000.0;

/// The stages every frame runs (shadow map, G-buffer, direct light, reduce and upsample,
/// exposure, tone map, read-back and encoding): 0.4 µs per output pixel and 2 ns per
/// shadow-map texel, measured with `none` at 32² … 640×480 and shadow maps of 1024² … 4096².
pub fn shared(shape: &FrameShape, cost: &mut Cost) {
    cost.add("per-pixel stages (pixels)", shape.pixels(), 400.0);
    let faces = f64::from(shape.light_faces);
    cost.add(
        "shadow map (faces × shadow_map_size²)",
        faces * f64::from(shape.shadow_map_size).powi(2),
        2.0,
    );
    cost.add(
        "shadow map triangles (faces × triangles)",
        faces * shape.triangles as f64,
        NS_PER_TRIANGLE,
    );
}

/// A reflective shadow map of `gi.rsm_size` (the RSM-based methods): 100 reference ns per
/// texel for its several targets (measured with VPLs from an RSM of 2048² against 64², at
/// 32×32, with three targets of 40 bytes a texel; the glossy senders' fourth, 16 bytes more,
/// is not yet measured: `bench/gpu-run.sh` times the `rsm` stage at 2048²).
pub fn rsm(gi: &GiParams, shape: &FrameShape, cost: &mut Cost) {
    cost.add("RSM (faces × rsm_size²)", shape.rsm_texels(gi), 100.0);
    cost.add(
        "RSM triangles (faces × triangles)",
        f64::from(shape.light_faces) * shape.triangles as f64,
        NS_PER_TRIANGLE,
    );
}

/// Which way a parameter lowers a cost.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cheaper {
    /// A smaller value costs less (`vpl_count`).
    Lower,
    /// A larger value costs less (`interleave`).
    Higher,
}

/// A parameter of `render.gi` that scales a cost: what a refusal names, with the value that
/// would fit. Its range is the one `/v1/server` describes for it.
#[derive(Clone, Copy)]
pub struct Knob {
    /// The parameter (an integer).
    pub param: &'static Param,
    pub cheaper: Cheaper,
    /// The values it takes, where not every integer of its range is one (ascending).
    pub choices: &'static [u32],
}

impl Knob {
    /// A parameter that costs less the lower it is, over every integer of its range.
    pub const fn lower(param: &'static Param) -> Self {
        Self {
            param,
            cheaper: Cheaper::Lower,
            choices: &[],
        }
    }

    /// The field under `render.gi`.
    pub fn field(&self) -> &'static str {
        self.param.name
    }

    pub fn get(&self, gi: &GiParams) -> u32 {
        self.param.u32(gi)
    }

    pub fn set(&self, gi: &mut GiParams, value: u32) {
        gi.set(self.param.name, value);
    }
}

/// `indirect_downscale`, for the methods the renderer runs at a reduced resolution.
pub const DOWNSCALE_KNOB: Knob = Knob {
    param: &INDIRECT_DOWNSCALE,
    cheaper: Cheaper::Higher,
    choices: &[1, 2, 4],
};

/// The value of a knob within `min..=max` closest to `current` that keeps `cost_of` within
/// `budget_ns`, if any: costs are monotone in each knob, so a bisection finds it.
pub fn fitting_value(
    gi: &GiParams,
    knob: &Knob,
    (min, max): (u32, u32),
    budget_ns: f64,
    cost_of: &dyn Fn(&GiParams) -> f64,
) -> Option<u32> {
    let current = knob.get(gi).clamp(min, max);
    let fits = |v: u32| {
        let mut g = gi.clone();
        knob.set(&mut g, v);
        cost_of(&g) <= budget_ns
    };
    if fits(current) {
        return Some(current);
    }
    if !knob.choices.is_empty() {
        // The fitting choice nearest `current` on the cheaper side.
        let mut cheaper = knob
            .choices
            .iter()
            .copied()
            .filter(|&v| match knob.cheaper {
                Cheaper::Lower => v < current && v >= min,
                Cheaper::Higher => v > current && v <= max,
            });
        return match knob.cheaper {
            Cheaper::Lower => cheaper.rev().find(|&v| fits(v)),
            Cheaper::Higher => cheaper.find(|&v| fits(v)),
        };
    }
    // `good` fits, `bad` does not; they close in on the fitting value nearest `current`.
    let (mut good, mut bad) = match knob.cheaper {
        Cheaper::Lower => (min, current),
        Cheaper::Higher => (max, current),
    };
    if !fits(good) {
        return None;
    }
    while good.abs_diff(bad) > 1 {
        let mid = good / 2 + bad / 2 + (good % 2 + bad % 2) / 2;
        if fits(mid) {
            good = mid;
        } else {
            bad = mid;
        }
    }
    Some(good)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape() -> FrameShape {
        FrameShape {
            width: 64,
            height: 48,
            shadow_map_size: 1024,
            lights: 1,
            light_faces: 1,
            environment: None,
            directional_faces: 1,
            triangles: 1000,
            set_units: 0,
            all_bounces: true,
        }
    }

    #[test]
    fn an_environment_is_lights_for_methods_that_do_not_sample_it() {
        let with_sky = FrameShape {
            environment: Some(8),
            ..shape()
        };
        let lit = with_sky.lit_by(false);
        assert_eq!((lit.lights, lit.light_faces, lit.environment), (9, 9, None));
        let sampled = with_sky.lit_by(true);
        assert_eq!(
            (sampled.lights, sampled.light_faces, sampled.environment),
            (1, 1, Some(8))
        );
        assert_eq!(shape().lit_by(false).lights, 1);
        let cascades = FrameShape {
            directional_faces: 2,
            ..with_sky
        };
        assert_eq!(cascades.lit_by(false).light_faces, 17);
    }

    #[test]
    fn costs_add_their_terms_and_say_which_dominate() {
        let mut cost = Cost::default();
        cost.add("a", 10.0, 3.0);
        cost.add("b", 0.0, 5.0);
        cost.add("c", 1.0, 90.0);
        assert_eq!(cost.terms().len(), 2, "a term of no items is left out");
        assert_eq!(cost.ns(), 120.0);
        assert!((cost.seconds(2.0) - 60e-9).abs() < 1e-18);
        assert_eq!(cost.breakdown(), "c 75 %, a 25 %");
        let mut frame = Cost::default();
        shared(&shape(), &mut frame);
        assert!(frame.ns() > 0.0);
    }

    #[test]
    fn the_fitting_value_is_the_largest_that_fits_and_its_neighbour_does_not() {
        use crate::gi::reference::params::SPP;
        let knob = Knob::lower(&SPP);
        let cost_of = |g: &GiParams| f64::from(SPP.u32(g)) * 7.0;
        let gi = GiParams::new(crate::gi::reference::REFERENCE).with("spp", 200);
        for budget in [7.0, 8.0, 700.0, 1399.0, 1400.0] {
            let v = fitting_value(&gi, &knob, (1, 256), budget, &cost_of).expect("fits");
            assert!(cost_of(&gi.clone().with("spp", v)) <= budget);
            assert!(cost_of(&gi.clone().with("spp", v + 1)) > budget || v == 200);
        }
        assert_eq!(fitting_value(&gi, &knob, (1, 256), 6.0, &cost_of), None);
        // A knob that is cheaper when larger (a block side, say) searches upwards.
        const BLOCK: Param = Param::integer("block", 1, (1, 16), "a block's side");
        let block = Knob {
            param: &BLOCK,
            cheaper: Cheaper::Higher,
            choices: &[],
        };
        let per_block = |g: &GiParams| 4096.0 / f64::from(BLOCK.u32(g)).powi(2);
        let method = crate::gi::methods().next().expect("a registered method");
        let gi = GiParams::new(method).with("block", 1);
        assert_eq!(
            fitting_value(&gi, &block, (1, 16), 300.0, &per_block),
            Some(4)
        );
        // A knob with choices only ever names one of them.
        let reduced = |g: &GiParams| 4096.0 / f64::from(INDIRECT_DOWNSCALE.u32(g)).powi(2);
        let full = GiParams::new(method).with("indirect_downscale", 1);
        let fit = |budget| fitting_value(&full, &DOWNSCALE_KNOB, (1, 4), budget, &reduced);
        assert_eq!(fit(5000.0), Some(1));
        assert_eq!(fit(1024.0), Some(2));
        assert_eq!(fit(1000.0), Some(4), "3 would fit too, but is no choice");
        assert_eq!(fit(100.0), None);
    }
}
