//! Per-stage timing of a frame.
//!
//! With timestamp queries the whole frame is one command buffer and a timestamp is written on
//! the encoder before and after every stage (timestamps attached to a pass read near zero on
//! some drivers, lavapipe among them). Without them each stage is submitted on its own and timed
//! by the CPU until the GPU is idle, which is slower and says so in [`TimingSource`].

use super::{GpuContext, GpuError};
use std::time::Instant;

/// A pipeline stage: the index frame headers carry and the name reports, metrics and
/// `/v1/server` use. The shared passes declare theirs in `passes::stages`, each GI method its
/// own (`gi/<method>/stages.rs`); the registry (`gi::stages`) checks that no two share an index
/// or a name and that the indices run 0..N without a gap. An index never changes once
/// released: a new stage takes the next free one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Stage {
    index: u16,
    name: &'static str,
}

impl Stage {
    pub const fn new(index: u16, name: &'static str) -> Self {
        Self { index, name }
    }

    /// The index frame headers carry (into `/v1/server`'s `stages`).
    pub const fn index(self) -> u16 {
        self.index
    }

    pub const fn name(self) -> &'static str {
        self.name
    }
}

impl serde::Serialize for Stage {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name)
    }
}

impl std::fmt::Display for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name)
    }
}

/// Where the stage times came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TimingSource {
    GpuTimestamps,
    CpuWallClock,
}

impl TimingSource {
    /// What a report says of its stage times on an adapter (`is_cpu`: a software one), when
    /// they cannot be trusted one by one ([`lightcast_protocol::CPU_TIMESTAMPS_NOTE`]).
    pub fn note(self, is_cpu: bool) -> Option<String> {
        (is_cpu && self == Self::GpuTimestamps)
            .then(|| lightcast_protocol::CPU_TIMESTAMPS_NOTE.to_string())
    }
}

/// Time one stage took.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StageTiming {
    pub stage: Stage,
    pub ms: f64,
    /// The stage's output was reused from an earlier frame made from the same inputs
    /// ([`crate::passes::reuse`]): no GPU work this frame, `ms` 0.
    pub reused: bool,
    /// The stage's output serves this many sessions' frames (made once for them all:
    /// `gi::lightskin::shared`), so each frame's share of its cost is its maker's `ms` over
    /// this; 0: it serves this frame alone.
    pub shared_by: u16,
}

impl StageTiming {
    /// A stage that ran this frame.
    pub fn ran(stage: Stage, ms: f64) -> Self {
        Self {
            stage,
            ms,
            reused: false,
            shared_by: 0,
        }
    }

    /// A stage whose output an earlier frame made.
    pub fn reused(stage: Stage) -> Self {
        Self {
            stage,
            ms: 0.0,
            reused: true,
            shared_by: 0,
        }
    }
}

/// Most stages a frame may time, a repeated one counted each time (a multi-bounce render may
/// add up to 16 bounces of three stages); a frame that names more is a programming error
/// caught in tests.
const MAX_STAGES: u32 = 64;

/// Query storage reused from frame to frame.
pub struct FrameTimer {
    queries: Option<Queries>,
}

struct Queries {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    period_ns: f64,
}

/// Bytes of a staging buffer that receives one frame's timestamps.
pub const TIMESTAMP_STAGING_BYTES: u64 = MAX_STAGES as u64 * 2 * 8;

/// A `MAP_READ` buffer for one frame's timestamps (frames in flight need one each).
pub fn timestamp_staging(device: &wgpu::Device) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("timestamp readback"),
        size: TIMESTAMP_STAGING_BYTES,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    })
}

/// Stage times of a submitted frame: known already (CPU wall clock) or still in a staging
/// buffer the GPU will fill.
pub struct PendingTimings {
    names: Vec<Stage>,
    ready: Vec<StageTiming>,
    reused: Vec<(usize, Stage)>,
    shared: Vec<(Stage, u16)>,
    staging: Option<(wgpu::Buffer, f64)>,
}

impl PendingTimings {
    /// Starts mapping the staging buffer (see [`super::readback::PendingMap`]).
    pub fn begin(self) -> TimingsMap {
        TimingsMap {
            map: self
                .staging
                .map(|(buffer, period)| (super::readback::PendingMap::new(&buffer), period)),
            names: self.names,
            ready: self.ready,
            reused: self.reused,
            shared: self.shared,
        }
    }
}

/// Timestamps being mapped.
pub struct TimingsMap {
    names: Vec<Stage>,
    ready: Vec<StageTiming>,
    reused: Vec<(usize, Stage)>,
    shared: Vec<(Stage, u16)>,
    map: Option<(super::readback::PendingMap, f64)>,
}

impl TimingsMap {
    /// The stage times, in the order each stage first ran (a reused one, at 0 ms, where it
    /// would have run), once the GPU work they time has finished (the caller polled).
    pub fn finish(self) -> Result<Vec<StageTiming>, GpuError> {
        let ran = match self.map {
            None => self.ready,
            Some((map, period_ns)) => {
                let bytes = map.finish()?;
                let ticks: &[u64] = bytemuck::cast_slice(&bytes);
                self.names
                    .iter()
                    .enumerate()
                    .map(|(i, &stage)| {
                        let ticks = ticks[2 * i + 1].saturating_sub(ticks[2 * i]);
                        StageTiming::ran(stage, ticks as f64 * period_ns / 1e6)
                    })
                    .collect()
            }
        };
        let mut timings = sum_repeated(with_reused(ran, self.reused));
        for (stage, sessions) in self.shared {
            for t in timings.iter_mut().filter(|t| t.stage == stage) {
                t.shared_by = sessions;
            }
        }
        Ok(timings)
    }
}

/// `ran` (one entry per stage run, in order) with each reused stage put back where it came
/// (`(n, stage)`: after the first n stages that ran).
fn with_reused(ran: Vec<StageTiming>, reused: Vec<(usize, Stage)>) -> Vec<StageTiming> {
    let mut out = Vec::with_capacity(ran.len() + reused.len());
    let mut reused = reused.into_iter().peekable();
    for (i, t) in ran.into_iter().enumerate() {
        while let Some((_, stage)) = reused.next_if(|(at, _)| *at <= i) {
            out.push(StageTiming::reused(stage));
        }
        out.push(t);
    }
    out.extend(reused.map(|(_, stage)| StageTiming::reused(stage)));
    out
}

/// One entry per stage: a stage that ran several times in a frame (a bounce each) reports the
/// sum, where it first ran, so frame headers and tables name each stage once.
fn sum_repeated(timings: Vec<StageTiming>) -> Vec<StageTiming> {
    let mut summed: Vec<StageTiming> = Vec::with_capacity(timings.len());
    for t in timings {
        match summed.iter_mut().find(|s| s.stage == t.stage) {
            Some(s) => s.ms += t.ms,
            None => summed.push(t),
        }
    }
    summed
}

impl FrameTimer {
    pub fn new(ctx: &GpuContext) -> Self {
        let queries = ctx.timestamps.then(|| {
            let bytes = TIMESTAMP_STAGING_BYTES;
            Queries {
                set: ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("stage timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: MAX_STAGES * 2,
                }),
                resolve: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timestamp resolve"),
                    size: bytes,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                period_ns: f64::from(ctx.queue.get_timestamp_period()),
            }
        });
        Self { queries }
    }

    pub fn source(&self) -> TimingSource {
        if self.queries.is_some() {
            TimingSource::GpuTimestamps
        } else {
            TimingSource::CpuWallClock
        }
    }

    /// Starts recording a frame's stages.
    pub fn begin<'a>(&'a mut self, ctx: &'a GpuContext) -> FrameStages<'a> {
        FrameStages {
            ctx,
            timer: self,
            encoder: None,
            names: Vec::new(),
            wall: Vec::new(),
            reused: Vec::new(),
            shared: Vec::new(),
            submitted: None,
        }
    }
}

/// Records the stages of one frame; see the module docs for the two modes.
pub struct FrameStages<'a> {
    ctx: &'a GpuContext,
    timer: &'a mut FrameTimer,
    encoder: Option<wgpu::CommandEncoder>,
    names: Vec<Stage>,
    wall: Vec<StageTiming>,
    /// Stages reused from an earlier frame, each after how many stages had run.
    reused: Vec<(usize, Stage)>,
    /// Stages whose output serves several sessions' frames, with how many.
    shared: Vec<(Stage, u16)>,
    submitted: Option<wgpu::SubmissionIndex>,
}

impl<'a> FrameStages<'a> {
    /// The device the frame is encoded for (a stage making bind groups for its targets).
    pub fn device(&self) -> &'a wgpu::Device {
        &self.ctx.device
    }
}

impl FrameStages<'_> {
    fn encoder(&mut self) -> &mut wgpu::CommandEncoder {
        let device = &self.ctx.device;
        self.encoder.get_or_insert_with(|| {
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            })
        })
    }

    /// Records that a stage's output is reused from an earlier frame: nothing is encoded.
    pub fn reused(&mut self, name: Stage) {
        self.reused.push((self.names.len(), name));
    }

    /// Records that a stage's output (made or reused by this frame) serves `sessions`
    /// sessions' frames ([`StageTiming::shared_by`]).
    pub fn shared(&mut self, name: Stage, sessions: u16) {
        self.shared.push((name, sessions));
    }

    /// Encodes one named stage.
    pub fn stage(
        &mut self,
        name: Stage,
        encode: impl FnOnce(&mut wgpu::CommandEncoder),
    ) -> Result<(), GpuError> {
        let index = self.names.len() as u32;
        assert!(
            index < MAX_STAGES,
            "more than {MAX_STAGES} stages in a frame"
        );
        self.names.push(name);
        match &self.timer.queries {
            Some(_) => {
                self.write_timestamp(index * 2);
                encode(self.encoder());
                self.write_timestamp(index * 2 + 1);
            }
            None => {
                let start = Instant::now();
                encode(self.encoder());
                self.submit();
                self.ctx.wait_idle()?;
                self.wall
                    .push(StageTiming::ran(name, start.elapsed().as_secs_f64() * 1e3));
            }
        }
        Ok(())
    }

    fn write_timestamp(&mut self, index: u32) {
        if let Some(set) = self.timer.queries.as_ref().map(|q| q.set.clone()) {
            self.encoder().write_timestamp(&set, index);
        }
    }

    fn submit(&mut self) {
        if let Some(encoder) = self.encoder.take() {
            self.submitted = Some(self.ctx.queue.submit([encoder.finish()]));
        }
    }

    /// Submits what is left without waiting; the timestamps are copied into `staging` (a
    /// [`timestamp_staging`] buffer not in use by another frame in flight). Returns the last
    /// submission, whose completion makes every result of the frame readable.
    pub fn submit_frame(
        mut self,
        staging: &wgpu::Buffer,
    ) -> (PendingTimings, Option<wgpu::SubmissionIndex>) {
        let count = self.names.len() as u32;
        let queries = self
            .timer
            .queries
            .as_ref()
            .map(|q| (q.set.clone(), q.resolve.clone(), q.period_ns));
        let staging = match queries {
            Some((set, resolve, period_ns)) if count > 0 => {
                let encoder = self.encoder();
                encoder.resolve_query_set(&set, 0..count * 2, &resolve, 0);
                encoder.copy_buffer_to_buffer(&resolve, 0, staging, 0, u64::from(count) * 16);
                Some((staging.clone(), period_ns))
            }
            _ => None,
        };
        self.submit();
        (
            PendingTimings {
                names: self.names,
                ready: self.wall,
                reused: self.reused,
                shared: self.shared,
                staging,
            },
            self.submitted,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reused_stage_is_listed_where_it_would_have_run() {
        let [shadow, gbuffer, rsm, light] = [0, 1, 2, 3].map(|i| Stage::new(i, "stage"));
        let reused = StageTiming::reused;
        let ran = vec![StageTiming::ran(gbuffer, 1.0), StageTiming::ran(light, 2.0)];
        assert_eq!(
            with_reused(ran.clone(), vec![(0, shadow), (1, rsm)]),
            vec![
                reused(shadow),
                StageTiming::ran(gbuffer, 1.0),
                reused(rsm),
                StageTiming::ran(light, 2.0)
            ]
        );
        assert_eq!(
            with_reused(ran.clone(), vec![(2, rsm)]),
            vec![ran[0].clone(), ran[1].clone(), reused(rsm)]
        );
    }

    #[test]
    fn a_repeated_stage_reports_its_sum_where_it_first_ran() {
        let t = StageTiming::ran;
        let [first, light, pull, shade] = [0, 1, 2, 3].map(|i| Stage::new(i, "stage"));
        let frame = vec![
            t(first, 1.0),
            t(light, 2.0),
            t(pull, 0.5),
            t(light, 3.0),
            t(pull, 0.25),
            t(shade, 4.0),
        ];
        assert_eq!(
            sum_repeated(frame),
            vec![t(first, 1.0), t(light, 5.0), t(pull, 0.75), t(shade, 4.0)]
        );
    }
}
