//! `none`: direct light only. Its one stage clears the indirect buffer, which the direct-light
//! pass adds in (the buffer is shared by every method, so it may hold an earlier frame's light).

use super::params::MethodTable;
use super::{FrameInputs, GiError, Method, MethodEntry, ProgressBuffer};
use crate::gpu::timing::{FrameStages, Stage};
use lightcast_protocol::{GiMethod, GiParams};
use std::any::{Any, TypeId};

/// The method's name.
pub const NONE: GiMethod = GiMethod::new("none");

/// The indirect buffer cleared.
pub const INDIRECT_CLEAR: Stage = Stage::new(9, "indirect_clear");

pub struct NoIndirect;

pub const ENTRY: MethodEntry = MethodEntry {
    tables: &[MethodTable {
        method: crate::gi::none::NONE,
        summary: "Direct light only.",
        progressive: false,
        params: &[],
        views: &[],
        testing: crate::gi::params::Testing {
            small: |_| GiParams::new(NONE),
            scale_tolerance: crate::gi::params::SCALE_TOLERANCE,
            exact_at_powers_of_two: true,
        },
        senders: |_| crate::gi::params::Senders::Full,
    }],
    type_id: TypeId::of::<NoIndirect>,
    validate: |_, _| Ok(()),
    check_table: |_| Ok(()),
    create: |_| Ok(Box::new(NoIndirect)),
    precompute: None,
    cost: |_, _, _| {},
    knobs: &[],
    shaders: &[],
    stages: &[INDIRECT_CLEAR],
    limits: &[],
    downscales: false,
    samples_environment: false,
    follows_moved_nodes: super::follows_every_pose,
    bench: None,
};

impl Method for NoIndirect {
    fn encode(
        &mut self,
        frame: &FrameInputs,
        stages: &mut FrameStages,
    ) -> Result<Option<ProgressBuffer>, GiError> {
        stages.stage(INDIRECT_CLEAR, |e| {
            e.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("clear indirect"),
                color_attachments: &[Some(crate::passes::cleared_attachment(
                    &frame.indirect.view,
                ))],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
        })?;
        Ok(None)
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}
