//! Resident-memory probe (issue 15): renders many tiny frames and prints the process's resident
//! memory and number of memory mappings, so per-frame growth can be told apart by where it
//! happens.
//!
//! ```text
//! cargo run --release -p lightcast-server --example memory_probe -- MODE [FRAMES]
//! ```
//! MODE:
//! - `none`, `lightskin`, `brsm`: our renderer on the Cornell box at 32×32 with that GI method;
//! - `bare-uniform`, `bare-storage`: a bare wgpu loop (no lightcast code) dispatching one
//!   compute shader that branches on a parameter read from a uniform, or from a read-only
//!   storage buffer.
//!
//! On lavapipe (Mesa 22.3) `bare-uniform` grows by one JIT-compiled shader variant per
//! dispatch (new executable mappings every frame) while `bare-storage` stays flat: the driver
//! inlines uniform values that steer control flow and recompiles at every dispatch without
//! freeing the previous variant. That is why every pass binds its parameters as storage
//! (`passes::PARAMS_BINDING`).
use lightcast_server::gi::lightskin::caches;
use lightcast_server::gi::lightskin::LightSkin;
use lightcast_server::gi::GiParams;
use lightcast_server::gpu::{BackendChoice, GpuContext};
use lightcast_server::passes::exposure::Exposure;
use lightcast_server::renderer::{RenderSettings, Renderer};
use lightcast_server::scene::{default_light, procedural};

/// VmRSS in KiB and the number of mappings of this process.
fn memory() -> anyhow::Result<(u64, usize)> {
    let status = std::fs::read_to_string("/proc/self/status")?;
    let rss = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .ok_or_else(|| anyhow::anyhow!("no VmRSS in /proc/self/status"))?;
    let maps = std::fs::read_to_string("/proc/self/maps")?.lines().count();
    Ok((rss, maps))
}

/// A compute shader large enough for lavapipe to consider inlining (over 100 SSA values) whose
/// branches depend on `p.kind`: a 3×3 loop around a branch on a parameter, the shape of the
/// PCF shadow lookup in `shaders/lights.wgsl`.
fn branchy_shader(address_space: &str) -> String {
    format!(
        "struct P {{ kind: u32, scale: f32, pad0: u32, pad1: u32 }}
         @group(0) @binding(0) var<storage, read_write> out: array<f32>;
         @group(0) @binding(1) var<{address_space}> p: P;
         @compute @workgroup_size(64)
         fn main(@builtin(global_invocation_id) id: vec3<u32>) {{
             var x = f32(id.x) * p.scale;
             for (var j = 0; j < 3; j++) {{
                 for (var k = 0; k < 3; k++) {{
                     var y = x + f32(j) * 0.3 - f32(k) * 0.2;
                     if p.kind == 0u {{
                         y = sin(y) * 1.5 + cos(y * 0.7) * distance(vec3(y), vec3(1.0, 2.0, 3.0));
                     }} else if p.kind == 1u {{
                         y = sqrt(abs(y)) + exp(-y * y) * 3.0 + dot(normalize(vec3(y, 1.0, 2.0)), vec3(0.5));
                     }} else {{
                         y = fract(y * 13.1) + log(1.0 + abs(y)) * length(vec2(y, 0.5));
                     }}
                     x += select(0.0, y, y > p.scale);
                 }}
             }}
             out[id.x] = x;
         }}"
    )
}

struct Bare {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
}

impl Bare {
    fn new(ctx: &GpuContext, uniform: bool) -> Self {
        let device = &ctx.device;
        let source = branchy_shader(if uniform { "uniform" } else { "storage, read" });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("branchy"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("branchy"),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let buffer = |size, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let out = buffer(4 * 1024, wgpu::BufferUsages::STORAGE);
        let params_usage = if uniform {
            wgpu::BufferUsages::UNIFORM
        } else {
            wgpu::BufferUsages::STORAGE
        };
        let params = buffer(16, params_usage | wgpu::BufferUsages::COPY_DST);
        let values: [u32; 4] = [1, 0.01f32.to_bits(), 0, 0];
        ctx.queue
            .write_buffer(&params, 0, bytemuck::cast_slice(&values));
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: out.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: params.as_entire_binding(),
                },
            ],
        });
        Self {
            pipeline,
            bind_group,
        }
    }

    fn frame(&self, ctx: &GpuContext) -> anyhow::Result<()> {
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(16, 1, 1);
        }
        ctx.queue.submit([encoder.finish()]);
        ctx.device.poll(wgpu::PollType::wait_indefinitely())?;
        Ok(())
    }
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let mode = args.get(1).map(String::as_str).unwrap_or("none");
    let frames: usize = match args.get(2) {
        Some(n) => n.parse()?,
        None => 500,
    };
    let ctx = GpuContext::new(BackendChoice::Auto)?;
    eprintln!("adapter: {}", ctx.info.name);

    let mut step: Box<dyn FnMut() -> anyhow::Result<()>> = match mode {
        "bare-uniform" | "bare-storage" => {
            let bare = Bare::new(&ctx, mode == "bare-uniform");
            let ctx = ctx.clone();
            Box::new(move || bare.frame(&ctx))
        }
        "none" | "lightskin" | "brsm" => {
            let scene = procedural::cornell_box();
            let method = match mode {
                "lightskin" => lightcast_server::gi::lightskin::LIGHTSKIN,
                "brsm" => lightcast_server::gi::lightskin::BRSM,
                _ => lightcast_server::gi::none::NONE,
            };
            let settings = RenderSettings {
                width: 32,
                height: 32,
                camera: default_light::default_camera(&scene),
                lights: vec![default_light::default_light(&scene)],
                environment: None,
                exposure: Exposure::Auto,
                shadow_map_size: 256,
                capture_hdr: false,
                debug_view: lightcast_protocol::View::FINAL,
                gi: GiParams::new(method)
                    .with("rsm_size", 32)
                    .with("view_samples", 64)
                    .with("val_count", 256),
                history: None,
                still: false,
                yuv420: false,
                poses: Vec::new(),
                pick: None,
            };
            let set =
                caches::precompute(&scene, &caches::CacheParams::for_scene(&scene), &mut |_| {})?;
            let mut renderer = Renderer::new(ctx.clone(), scene);
            renderer
                .gi::<LightSkin>()
                .expect("LightSkin is registered")
                .set_caches(&set)?;
            Box::new(move || renderer.render(&settings).map(drop).map_err(Into::into))
        }
        other => anyhow::bail!("unknown mode {other:?}; see the doc comment"),
    };
    for i in 0..frames {
        step()?;
        if i % 100 == 0 || i + 1 == frames {
            let (rss, maps) = memory()?;
            println!("{mode} frame {i}: VmRSS {rss} KiB, {maps} mappings");
        }
    }
    Ok(())
}
