//! Resident memory must not grow with the number of frames rendered. On lavapipe it grew by
//! ~450 KiB per frame without GI and ~1.3 MiB with it, until every pass bound its parameters
//! as storage instead of uniform buffers (issue 15; see `passes::PARAMS_BINDING`).
//!
//! The other tests of this binary run in the same process and allocate as they please, so the
//! measurement runs in a child process that runs only this test.

use super::support;
use lightcast_server::renderer::Renderer;
use lightcast_server::scene::{default_light, procedural};

const CHILD_ENV: &str = "LIGHTCAST_FRAME_MEMORY_CHILD";
const TEST_NAME: &str = "frame_memory::resident_memory_stays_flat_over_hundreds_of_frames";
/// Frames before the first measurement: pipelines, targets, ring buffers and the allocator's
/// arenas settle.
const WARM_UP: usize = 30;
/// Frames between the two measurements.
const FRAMES: usize = 150;
/// Allowed resident growth over [`FRAMES`] frames: 32 KiB per frame, a fourteenth of the
/// smallest leak this test was written against (450 KiB per frame without GI).
const MAX_GROWTH_KIB: u64 = 32 * FRAMES as u64;

fn resident_kib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .expect("VmRSS in /proc/self/status")
}

/// Renders [`WARM_UP`] + [`FRAMES`] frames of 32² per registered GI method (at its small
/// setting, after its precomputation) and prints the resident size before and after the
/// measured frames.
fn measure_in_child() {
    let ctx = support::gpu();
    let scene = procedural::cornell_box();
    let mut renderer = Renderer::new(ctx, scene.clone());
    for method in lightcast_server::gi::methods() {
        let mut settings = support::settings(
            32,
            32,
            default_light::default_camera(&scene),
            default_light::default_light(&scene),
        );
        settings.capture_hdr = false;
        settings.gi = support::small(method, &scene);
        support::precompute(&mut renderer, &settings.gi);
        let started = std::time::Instant::now();
        let mut before = 0;
        for i in 0..WARM_UP + FRAMES {
            if i == WARM_UP {
                before = resident_kib();
            }
            renderer.render(&settings).expect("frame");
        }
        println!("frame-memory {method} {before} {}", resident_kib());
        eprintln!("{method}: {:.1} s", started.elapsed().as_secs_f64());
    }
}

#[test]
fn resident_memory_stays_flat_over_hundreds_of_frames() {
    if std::env::var_os(CHILD_ENV).is_some() {
        measure_in_child();
        return;
    }
    let exe = std::env::current_exe().expect("test binary path");
    let output = std::process::Command::new(exe)
        .args([TEST_NAME, "--exact", "--nocapture", "--test-threads=1"])
        .env(CHILD_ENV, "1")
        .output()
        .expect("run the measuring child");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "measuring child failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let lines: Vec<(&str, u64, u64)> = stdout
        .lines()
        .filter_map(|l| {
            // The harness's "test … " may precede the first line on the same line.
            let at = l.find("frame-memory ")?;
            let mut f = l[at + "frame-memory ".len()..].split_whitespace();
            Some((f.next()?, f.next()?.parse().ok()?, f.next()?.parse().ok()?))
        })
        .collect();
    assert_eq!(
        lines.len(),
        lightcast_server::gi::methods().count(),
        "one measurement per GI method in:\n{stdout}"
    );
    for (method, before, after) in lines {
        let growth = after.saturating_sub(before);
        eprintln!("{method}: VmRSS {before} → {after} KiB over {FRAMES} frames");
        assert!(
            growth <= MAX_GROWTH_KIB,
            "{method}: resident memory grew by {growth} KiB over {FRAMES} frames \
             ({} KiB per frame; at most {MAX_GROWTH_KIB} KiB allowed)",
            growth / FRAMES as u64
        );
    }
}
