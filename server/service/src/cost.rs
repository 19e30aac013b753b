//! Every request's cost, estimated before it runs and checked against this server's limits
//! (issue 30): a one-shot render (with its comparison render), each frame of a session (one
//! tick of the render loop: the render loop serves one frame at a time) and a precomputation a
//! request would start. A request over a limit is refused with 400 naming the parameter to
//! lower and the value of it that fits; nothing runs.
//!
//! The estimates are the methods' own formulas (`gi::cost`, each method's `cost`) in
//! reference nanoseconds; `--adapter-speed` says how many times faster than the reference
//! (lavapipe on 2 cores) this adapter is, `--max-frame-cost` how many estimated seconds one
//! submission (a session's frame, a one-shot's frame but for its path tracing) may take on it
//! while every other session waits, and `--max-request-cost` how many a one-shot may take in
//! all, its path tracing in chunks. Precomputations run on the CPU and are held to
//! `--max-precompute-cost` seconds of the reference's 2 cores.

use super::error::ApiError;
use crate::gi::cost::{self, Cost, FrameShape, Knob};
use crate::gi::precompute::{PrecomputeEntry, PrecomputeKey, SceneFacts};
use crate::gi::reference::params::SPP;
use lightcast_protocol::{GiMethod, GiParams, Limits};

/// `--adapter-speed`: `auto`, or how many times faster than the reference this adapter is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AdapterSpeed {
    Auto,
    Times(f64),
}

/// What `auto` takes a GPU to be: an H200 ran the compute-bound stages about 450 times faster
/// than the reference and its raster stages far less (`bench/results/gpu-h200-*`), so a
/// lower ratio keeps raster-heavy requests within their limit there too.
pub const GPU_SPEED: f64 = 256.0;

/// `auto` (`None`) or a positive finite number, as the `auto`-able flags take it.
fn auto_or_positive(s: &str, what: &str) -> Result<Option<f64>, String> {
    if s == "auto" {
        return Ok(None);
    }
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(Some(v)),
        _ => Err(format!("'{s}' is neither auto nor {what}")),
    }
}

impl std::str::FromStr for AdapterSpeed {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Ok(auto_or_positive(s, "a positive number")?.map_or(Self::Auto, Self::Times))
    }
}

/// `--max-frame-cost`: `auto`, or seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FrameCost {
    Auto,
    Seconds(f64),
}

impl std::str::FromStr for FrameCost {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Ok(auto_or_positive(s, "a positive number of seconds")?.map_or(Self::Auto, Self::Seconds))
    }
}

impl FrameCost {
    /// The limit on an adapter (`is_cpu`: a software one): lavapipe's frames may take up to
    /// 2 s (it is slow at everything, and cuts a dispatch of ~2.8 s short), a GPU's 0.1 s.
    pub fn resolve(self, is_cpu: bool) -> f64 {
        match self {
            Self::Seconds(v) => v,
            Self::Auto if is_cpu => 2.0,
            Self::Auto => 0.1,
        }
    }
}

impl AdapterSpeed {
    /// The speed of an adapter (`is_cpu`: a software one).
    pub fn resolve(self, is_cpu: bool) -> f64 {
        match self {
            Self::Times(v) => v,
            Self::Auto if is_cpu => 1.0,
            Self::Auto => GPU_SPEED,
        }
    }
}

/// A request's cost in reference ns, for a candidate set of GI parameters.
type CostOf<'a> = &'a dyn Fn(&GiParams) -> Cost;

const PRECOMPUTE_FLAG: &str = "--max-precompute-cost";
const FRAME_FLAG: &str = "--max-frame-cost";

/// How a frame's work reaches the GPU, which decides the limits it is held to.
#[derive(Clone, Copy, Debug)]
pub enum Submission {
    /// A session's frame: one submission per turn of the render loop, within
    /// `--max-frame-cost`.
    SessionFrame,
    /// A one-shot render: its path tracing (a `reference` frame, the comparison renders) in
    /// chunks (see [`chunk_spp`]), the whole within `--max-request-cost`; any other frame is
    /// one submission within `--max-frame-cost` as well.
    OneShot { compare: Option<Compared> },
}

/// What a one-shot render is compared with: `renders` reference renders of `spp` samples per
/// pixel each (the full light transport's, and the modelled transport's when the request
/// asks for it: `compare_modelled`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Compared {
    pub spp: u32,
    pub renders: u32,
}

impl Compared {
    /// What a refusal calls the request.
    fn what(self) -> &'static str {
        if self.renders > 1 {
            "this render and its comparisons"
        } else {
            "this render and its comparison"
        }
    }

    /// The cost of them all, the cost of one being `one`.
    fn cost(self, one: Cost) -> Cost {
        let mut all = Cost::default();
        for t in one.terms() {
            all.add(t.what, f64::from(self.renders), t.ns);
        }
        all
    }
}

/// How much one request may cost, in reference ns.
fn request_budget_ns(limits: &Limits) -> f64 {
    limits.max_request_seconds * 1e9 * limits.adapter_speed
}

/// The cost of one frame of `gi` on a frame of `shape` (its `set_units` replaced by those of
/// `gi`'s precomputed set, which `set_units` estimates).
pub fn frame_cost(gi: &GiParams, shape: FrameShape, set_units: &dyn Fn(&GiParams) -> u64) -> Cost {
    let shape = FrameShape {
        set_units: set_units(gi),
        ..shape
    }
    .lit_by(crate::gi::entry(gi.method).1.samples_environment);
    let mut total = Cost::default();
    cost::shared(&shape, &mut total);
    (crate::gi::entry(gi.method).1.cost)(gi, &shape, &mut total);
    total
}

/// The GI parameters of the render a one-shot of `gi` is compared with.
fn truth(gi: &GiParams, spp: u32) -> GiParams {
    let mut truth = gi.clone().with(SPP.name, spp);
    truth.method = crate::gi::reference::REFERENCE;
    truth
}

/// The estimated seconds on this server's adapter of a frame of `gi` and, with `compare`,
/// the reference renders it is compared with.
pub fn request_seconds(
    gi: &GiParams,
    shape: FrameShape,
    set_units: &dyn Fn(&GiParams) -> u64,
    compare: Option<Compared>,
    limits: &Limits,
) -> f64 {
    let compared = compare.map_or(0.0, |c| {
        c.cost(frame_cost(&truth(gi, c.spp), shape, set_units)).ns()
    });
    (frame_cost(gi, shape, set_units).ns() + compared) * 1e-9 / limits.adapter_speed
}

/// The samples per pixel of a one-shot `reference` whose request names none: as many as half
/// the request budget buys (its comparison included), at least `floor` (the default) and at
/// most this server's limit of `spp`. A fixed default was either noise (4 spp) or far over the deadline on a CPU
/// adapter; half leaves room for the rest of the request. The reference's own `spp` knob
/// finds it, as a refusal's fitting value is found.
pub fn one_shot_spp(
    gi: &GiParams,
    shape: FrameShape,
    set_units: &dyn Fn(&GiParams) -> u64,
    compare: Option<Compared>,
    limits: &Limits,
    floor: u32,
) -> u32 {
    let most = (SPP.max_on(Some(limits)) as u32).max(1);
    let floor = floor.clamp(1, most);
    let knobs = crate::gi::entry(crate::gi::reference::REFERENCE).1.knobs;
    let Some(knob) = knobs.iter().find(|k| k.field() == SPP.name) else {
        return floor;
    };
    let cost_of = |g: &GiParams| request_seconds(g, shape, set_units, compare, limits) * 1e9;
    let budget_ns = 0.5 * limits.max_request_seconds * 1e9;
    let start = gi.clone().with(SPP.name, most);
    cost::fitting_value(&start, knob, (floor, most), budget_ns, &cost_of).unwrap_or(floor)
}

/// Estimated seconds of adapter work one submission of a chunked render may take: on a GPU
/// ~100 ms keeps the other sessions' frames flowing between chunks; on a CPU adapter ~1 s
/// stays well below the ~2.8 s after which lavapipe silently cuts a dispatch short.
fn chunk_seconds(limits: &Limits) -> f64 {
    if limits.adapter_speed > 1.0 {
        0.1
    } else {
        1.0
    }
}

/// Samples per submission of a one-shot's path tracing (its own frame with the `reference`,
/// its comparisons with `compare`) when more of them than that would exceed
/// [`chunk_seconds`]; `None` when every path-traced render fits in one submission.
pub fn chunk_spp(
    gi: &GiParams,
    shape: FrameShape,
    compare: Option<Compared>,
    limits: &Limits,
) -> Option<u32> {
    let own = (gi.method == crate::gi::reference::REFERENCE).then(|| SPP.u32(gi));
    let most = own.into_iter().chain(compare.map(|c| c.spp)).max()?;
    let mut one_sample = Cost::default();
    (crate::gi::entry(crate::gi::reference::REFERENCE).1.cost)(
        &truth(gi, 1),
        &shape,
        &mut one_sample,
    );
    let per_chunk = chunk_seconds(limits) * 1e9 * limits.adapter_speed / one_sample.ns();
    let step = (per_chunk.floor() as u32).max(1);
    (step < most).then_some(step)
}

/// The range `/v1/server` describes for `field` of `method`.
fn range(method: GiMethod, field: &str, limits: &Limits) -> Option<(u32, u32)> {
    let info = crate::gi::describe_all(limits)
        .into_iter()
        .find(|m| m.method == method)?;
    let p = info.parameters.into_iter().find(|p| p.name == field)?;
    Some((p.min? as u32, p.max? as u32))
}

fn seconds(ns: f64, speed: f64) -> String {
    let s = ns * 1e-9 / speed;
    if s >= 100.0 {
        format!("{s:.0} s")
    } else {
        format!("{s:.2} s")
    }
}

/// What a refusal says about a cost over `budget_ns`: the estimate, its largest terms and the
/// limit's flag.
fn over(what: &str, cost: &Cost, budget_ns: f64, speed: f64, flag: &str) -> String {
    // Precomputations run on the CPU: their limit is in the reference's seconds.
    let on = if flag == PRECOMPUTE_FLAG {
        "on 2 CPU cores"
    } else {
        "on this adapter"
    };
    format!(
        "{what} is estimated at {} {on} ({}), over this server's limit of {} ({flag})",
        seconds(cost.ns(), speed),
        cost.breakdown(),
        seconds(budget_ns, speed),
    )
}

/// The first of `knobs` (in their order) with a value that brings `cost_of` within
/// `budget_ns`: `(field, value)`.
fn fitting_knob(
    gi: &GiParams,
    knobs: &[Knob],
    budget_ns: f64,
    cost_of: CostOf,
    limits: &Limits,
) -> Option<(&'static str, u32)> {
    let ns = |g: &GiParams| cost_of(g).ns();
    knobs.iter().find_map(|knob| {
        let range = range(gi.method, knob.field(), limits)?;
        let value = cost::fitting_value(gi, knob, range, budget_ns, &ns)?;
        Some((knob.field(), value))
    })
}

/// The refusal of `gi` whose `cost` exceeds `budget_ns`: naming `gi.<knob>` with the value
/// that fits, or, when no single parameter does, `fallback` (a field outside `gi`).
#[allow(clippy::too_many_arguments)]
fn refusal(
    what: &str,
    gi: &GiParams,
    cost: &Cost,
    budget_ns: f64,
    knobs: &[Knob],
    cost_of: CostOf,
    limits: &Limits,
    (flag, speed, fallback): (&str, f64, &str),
) -> ApiError {
    let message = over(what, cost, budget_ns, speed, flag);
    match fitting_knob(gi, knobs, budget_ns, cost_of, limits) {
        Some((field, value)) => {
            let verb = if knobs
                .iter()
                .find(|k| k.field() == field)
                .is_some_and(|k| k.cheaper == cost::Cheaper::Higher)
            {
                "at least"
            } else {
                "at most"
            };
            ApiError::field(
                format!("gi.{field}"),
                format!("{message}; {field} {verb} {value} fits"),
            )
        }
        None => ApiError::field(
            fallback,
            format!(
                "{message}; no single GI parameter brings it within the limit: lower \
                 width × height, or several GI parameters"
            ),
        ),
    }
}

/// Refuses a frame of `gi` (plus, for a one-shot render compared with the reference, the
/// comparison frames) over `--max-request-cost`. Field paths are relative to `render` but for
/// `compare_spp`.
pub fn check_frame(
    gi: &GiParams,
    shape: FrameShape,
    set_units: &dyn Fn(&GiParams) -> u64,
    submission: Submission,
    limits: &Limits,
) -> Result<(), ApiError> {
    let budget = request_budget_ns(limits);
    let speed = limits.adapter_speed;
    let own = |g: &GiParams| frame_cost(g, shape, set_units);
    let method = crate::gi::entry(gi.method).1;
    let mut knobs = method.knobs.to_vec();
    if method.downscales {
        knobs.push(cost::DOWNSCALE_KNOB);
    }
    let knobs = &knobs[..];
    let (compare, chunked) = match submission {
        Submission::SessionFrame => (None, false),
        Submission::OneShot { compare } => (compare, gi.method == crate::gi::reference::REFERENCE),
    };
    let cost = own(gi);
    // A frame submitted at once holds up every other session's: --max-frame-cost.
    let frame_budget = limits.max_frame_seconds * 1e9 * speed;
    if !chunked && cost.ns() > frame_budget {
        return Err(refusal(
            "this frame",
            gi,
            &cost,
            frame_budget,
            knobs,
            &own,
            limits,
            (FRAME_FLAG, speed, "width"),
        ));
    }
    let compared = compare.map(|c| c.cost(frame_cost(&truth(gi, c.spp), shape, set_units)));
    let compared_ns = compared.as_ref().map_or(0.0, Cost::ns);
    if cost.ns() + compared_ns <= budget {
        return Ok(());
    }
    let flags = ("--max-request-cost", speed, "width");
    let (Some(with), Some(compared)) = (compare, compared) else {
        return Err(refusal(
            "this frame",
            gi,
            &cost,
            budget,
            knobs,
            &own,
            limits,
            flags,
        ));
    };
    // The larger of the two frames is the one to make cheaper.
    if compared.ns() >= cost.ns() {
        let reference = crate::gi::entry(crate::gi::reference::REFERENCE).1.knobs;
        let spp_knob: Vec<Knob> = reference
            .iter()
            .filter(|k| k.field() == "spp")
            .copied()
            .collect();
        let of_truth = |g: &GiParams| with.cost(frame_cost(g, shape, set_units));
        let left = budget - cost.ns();
        if let Some((_, value)) =
            fitting_knob(&truth(gi, with.spp), &spp_knob, left, &of_truth, limits)
        {
            let mut both = cost.clone();
            for t in compared.terms() {
                both.add(t.what, 1.0, t.ns);
            }
            return Err(ApiError::field(
                "compare_spp",
                format!(
                    "{}; compare_spp at most {value} fits",
                    over(with.what(), &both, budget, speed, "--max-request-cost")
                ),
            ));
        }
    }
    let with_comparison = |g: &GiParams| {
        let mut c = own(g);
        c.add("comparison renders", 1.0, compared_ns);
        c
    };
    Err(refusal(
        with.what(),
        gi,
        &with_comparison(gi),
        budget,
        knobs,
        &with_comparison,
        limits,
        flags,
    ))
}

/// Refuses a new precomputation `key` (of `entry`, for GI parameters `gi` on a scene with
/// `facts`) estimated over `--max-precompute-cost`.
pub fn check_precompute(
    entry: &PrecomputeEntry,
    gi: &GiParams,
    key: &PrecomputeKey,
    facts: &SceneFacts,
    limits: &Limits,
) -> Result<(), ApiError> {
    let budget = limits.max_precompute_seconds * 1e9;
    let cost_of_key = |key: &PrecomputeKey| {
        let mut c = Cost::default();
        (entry.cost)(key, facts, &mut c);
        c
    };
    let cost = cost_of_key(key);
    if cost.ns() <= budget {
        return Ok(());
    }
    let cost_of = |g: &GiParams| match (entry.key)(g, facts) {
        Ok(k) => cost_of_key(&k),
        Err(_) => {
            let mut c = Cost::default();
            c.add("an invalid set", 1.0, f64::INFINITY);
            c
        }
    };
    let what = format!("building the {} of this scene", entry.label);
    Err(refusal(
        &what,
        gi,
        &cost,
        budget,
        entry.knobs,
        &cost_of,
        limits,
        (PRECOMPUTE_FLAG, 1.0, "gi.method"),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::reference::limits::MAX_SPP;

    const ONE_SHOT: Submission = Submission::OneShot { compare: None };

    fn limits(seconds: f64) -> Limits {
        let mut l = crate::service::config::tests::default_limits();
        l.max_request_seconds = seconds;
        l.max_frame_seconds = seconds;
        l.adapter_speed = 1.0;
        l
    }

    fn shape(width: u32, height: u32) -> FrameShape {
        FrameShape {
            width,
            height,
            shadow_map_size: 1024,
            lights: 1,
            light_faces: 1,
            environment: None,
            directional_faces: 1,
            triangles: 1090,
            set_units: 0,
            all_bounces: true,
        }
    }

    #[test]
    fn a_one_shot_reference_takes_the_samples_half_the_budget_buys() {
        let none = |_: &GiParams| 0;
        let reference = GiParams::new(crate::gi::reference::REFERENCE);
        let limits = limits(10.0);
        let spp = one_shot_spp(&reference, shape(320, 240), &none, None, &limits, 4);
        let seconds = |spp: u32| {
            let g = reference.clone().with("spp", spp);
            request_seconds(&g, shape(320, 240), &none, None, &limits)
        };
        assert!(spp > 4 && u64::from(spp) < MAX_SPP.of(&limits), "{spp}");
        assert!(seconds(spp) <= 5.0 && seconds(spp + 1) > 5.0, "{spp}");
        // A comparison shares the budget; a tiny frame gets the most the server allows; a
        // frame where even the default is over budget keeps the default (and is refused or
        // chunked as any other).
        let compared = |spp, renders| {
            let c = Some(Compared { spp, renders });
            one_shot_spp(&reference, shape(320, 240), &none, c, &limits, 4)
        };
        assert!(compared(256, 1) < spp);
        // Two comparison renders (the modelled transport's too) leave less.
        let (one, two) = (compared(spp / 4, 1), compared(spp / 4, 2));
        assert!(two < one && two > 4, "{two} {one}");
        assert_eq!(
            one_shot_spp(&reference, shape(2, 2), &none, None, &limits, 4),
            MAX_SPP.of(&limits) as u32
        );
        assert_eq!(
            one_shot_spp(&reference, shape(3840, 2160), &none, None, &limits, 4),
            4
        );
    }

    /// The repros: a 32×32 reference render with 256 spp and 16 bounces, and a 32×32
    /// `clustered` render with 65,536 VPLs at interleave 1 (CSSM and hard VPL shadows).
    #[test]
    fn the_repros_are_refused_naming_a_value_that_fits() {
        let limits = limits(10.0);
        let none = |_: &GiParams| 0;
        let reference = GiParams::new(crate::gi::reference::REFERENCE)
            .with("spp", 256)
            .with("bounces", 16);
        let e =
            check_frame(&reference, shape(32, 32), &none, ONE_SHOT, &limits).expect_err("refused");
        assert_eq!(
            e.body.field.as_deref(),
            Some("gi.spp"),
            "{}",
            e.body.message
        );
        let fits: u32 = e
            .body
            .message
            .rsplit("spp at most ")
            .next()
            .and_then(|v| v.split(' ').next())
            .and_then(|v| v.parse().ok())
            .expect("a value");
        let at = |spp| reference.clone().with("spp", spp);
        assert!(check_frame(&at(fits), shape(32, 32), &none, ONE_SHOT, &limits).is_ok());
        assert!(check_frame(&at(fits + 1), shape(32, 32), &none, ONE_SHOT, &limits).is_err());

        for visibility in [
            crate::gi::clustered::Visibility::Cssm,
            crate::gi::clustered::Visibility::VplShadows,
        ] {
            let clustered = GiParams::new(crate::gi::clustered::CLUSTERED)
                .with("vpl_count", 65_536)
                .with("interleave", 1)
                .with("cluster_count", 256)
                .with("kmeans_iterations", 64)
                .with("visibility", visibility.name());
            let e = check_frame(&clustered, shape(32, 32), &none, ONE_SHOT, &limits)
                .expect_err("refused");
            assert!(e.body.field.is_some(), "{}", e.body.message);
        }
    }

    #[test]
    fn a_frame_submitted_at_once_is_held_to_the_frame_limit_and_path_tracing_to_the_request_limit()
    {
        let mut limits = limits(10.0);
        limits.max_frame_seconds = 2.0;
        let none = |_: &GiParams| 0;
        // About 4 s of rays: in chunks as a one-shot, but one submission as a session frame.
        let reference = GiParams::new(crate::gi::reference::REFERENCE)
            .with("spp", 100)
            .with("bounces", 16);
        check_frame(&reference, shape(32, 32), &none, ONE_SHOT, &limits).expect("chunked");
        let e = check_frame(
            &reference,
            shape(32, 32),
            &none,
            Submission::SessionFrame,
            &limits,
        )
        .expect_err("one submission");
        assert_eq!(e.body.field.as_deref(), Some("gi.spp"));
        assert!(
            e.body.message.contains("--max-frame-cost"),
            "{}",
            e.body.message
        );
        // A BRSM frame of about 7 s is one submission either way.
        let brsm = GiParams::default()
            .with("val_count", 65_536)
            .with("rsm_size", 128)
            .with("view_samples", 32);
        let caches = |_: &GiParams| 6596;
        for submission in [ONE_SHOT, Submission::SessionFrame] {
            let e = check_frame(&brsm, shape(32, 32), &caches, submission, &limits)
                .expect_err("over the frame limit");
            assert_eq!(
                e.body.field.as_deref(),
                Some("gi.val_count"),
                "{}",
                e.body.message
            );
        }
    }

    #[test]
    fn cheap_frames_pass_and_a_comparison_counts() {
        let limits = limits(10.0);
        let none = |_: &GiParams| 0;
        let brsm = GiParams::default();
        check_frame(&brsm, shape(64, 48), &none, ONE_SHOT, &limits).expect("a small frame");
        check_frame(
            &brsm,
            shape(64, 48),
            &none,
            Submission::OneShot {
                compare: Some(Compared {
                    spp: 16,
                    renders: 2,
                }),
            },
            &limits,
        )
        .expect("a cheap comparison");
        let e = check_frame(
            &brsm,
            shape(64, 48),
            &none,
            Submission::OneShot {
                compare: Some(Compared {
                    spp: 256_000,
                    renders: 1,
                }),
            },
            &limits,
        )
        .expect_err("an expensive comparison");
        assert_eq!(
            e.body.field.as_deref(),
            Some("compare_spp"),
            "{}",
            e.body.message
        );
    }
}
