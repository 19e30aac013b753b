use super::*;
use crate::gi::lightskin::cache_key;
use crate::gi::lightskin::caches::{min_distance_for, CacheParams};
use crate::gi::lightskin::limits::{MAX_CACHES_PER_SET, MAX_TOTAL_CACHES};
use crate::gi::limits::GiLimit;
use crate::scene::procedural;
use std::sync::mpsc;
use std::time::Duration;

fn limits(max_scenes: u32) -> Limits {
    Limits {
        max_scenes,
        ..crate::service::config::tests::default_limits()
    }
}

fn params(d_eps: f32) -> PrecomputeKey {
    cache_key(
        &CacheParams {
            d_eps,
            theta_eps_degrees: 30.0,
        },
        0,
    )
}

/// The light caches a brsm frame asks for with `cache_distance`.
fn key_for(entry: &SceneEntry, d_eps: f32) -> Result<Option<PrecomputeKey>, ApiError> {
    entry.precompute_key(&GiParams::default().with("cache_distance", Some(d_eps)))
}

fn state(entry: &SceneEntry, p: &PrecomputeKey) -> Option<PrecomputeState> {
    lock(&entry.variants)
        .iter()
        .find(|v| v.key == *p)
        .map(|v| v.state)
}

/// A worker that reports each job's scene id and then waits for a go-ahead.
fn gated() -> (Arc<SceneRegistry>, mpsc::Receiver<String>, mpsc::Sender<()>) {
    let (seen_tx, seen) = mpsc::channel();
    let (go, go_rx) = mpsc::channel::<()>();
    let go_rx = Mutex::new(go_rx);
    let registry = SceneRegistry::with_workers(&limits(4), None, move |entry, _, _| {
        let _ = seen_tx.send(entry.id.clone());
        let _ = lock(&go_rx).recv();
    });
    (registry, seen, go)
}

const WAIT: Duration = Duration::from_secs(10);

/// A registry under `limits` whose worker does nothing.
fn idle(limits: &Limits) -> Arc<SceneRegistry> {
    SceneRegistry::with_workers(limits, None, |_, _, _| {})
}

/// `limits` with the GI limits `set`.
fn with_gi(mut limits: Limits, set: &[(&GiLimit, u64)]) -> Limits {
    for (limit, value) in set {
        limits.gi.insert(limit.name.into(), (*value).into());
    }
    limits
}

/// The light caches held over every scene.
fn caches_used(registry: &SceneRegistry) -> u64 {
    registry
        .budget()
        .gi_pool(&MAX_TOTAL_CACHES)
        .expect("a registered pool")
        .used()
}

#[test]
fn cache_sets_beyond_the_budgets_are_refused_before_anything_is_built() {
    let registry = idle(&limits(4));
    let entry = registry
        .detached(procedural::cornell_box(), 0.0)
        .expect("fits");
    let area = entry.facts.surface_area;
    // The smallest distance the format's own cap allows, which the server used to
    // suggest: about two million caches, far beyond one set's budget.
    let suggested = min_distance_for(area, crate::gi::lightskin::caches::MAX_CACHES) * 1.01;
    let e = key_for(&entry, suggested).expect_err("beyond --max-caches-per-set");
    assert_eq!(e.body.field.as_deref(), Some("gi.cache_distance"));
    assert!(
        e.body
            .message
            .contains("limit of 250000 per set (--max-caches-per-set)"),
        "{}",
        e.body.message
    );
    assert_eq!(caches_used(&registry), 0, "nothing taken");

    let tight = with_gi(
        limits(4),
        &[(&MAX_CACHES_PER_SET, 10_000), (&MAX_TOTAL_CACHES, 15_000)],
    );
    let registry = idle(&tight);
    let entry = registry
        .detached(procedural::cornell_box(), 0.0)
        .expect("fits");
    let smallest = min_distance_for(area, 10_000);
    let p = key_for(&entry, smallest)
        .expect("10,000 fit")
        .expect("brsm needs light caches");
    assert!(key_for(&entry, smallest * 0.95).is_err());
    assert!(matches!(registry.precomputed(&entry, &p), Now::Pending));
    let taken = caches_used(&registry);
    assert!((9_000..=10_000).contains(&taken), "{taken}");
    let e = key_for(&entry, smallest * 1.1).expect_err("the total is spent");
    assert_eq!(e.body.field.as_deref(), Some("gi.cache_distance"));
    assert!(
        e.body.message.contains("(--max-total-caches)"),
        "{}",
        e.body.message
    );
    assert!(
        key_for(&entry, smallest).is_ok(),
        "the set that exists is not counted twice"
    );
    drop(entry);
    // The precompute worker may still hold the queued build's handle for a moment (it
    // did under the full suite's load): the reservation goes with the last one.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while caches_used(&registry) != 0 && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    assert_eq!(caches_used(&registry), 0, "given back with the scene");
}

#[test]
fn built_sets_hold_their_real_count_and_are_refused_beyond_the_per_set_limit() {
    let registry = idle(&with_gi(limits(4), &[(&MAX_CACHES_PER_SET, 10_000)]));
    let entry = registry
        .detached(procedural::cornell_box(), 0.0)
        .expect("fits");
    let p = params(1.0);
    assert!(matches!(registry.precomputed(&entry, &p), Now::Pending));
    assert_eq!(
        entry.hold_built(&crate::gi::lightskin::PRECOMPUTE, &p, 7),
        Ok(())
    );
    assert_eq!(caches_used(&registry), 7);
    let e = entry
        .hold_built(&crate::gi::lightskin::PRECOMPUTE, &p, 10_001)
        .expect_err("over");
    assert!(e.contains("--max-caches-per-set"), "{e}");
}

#[test]
fn scenes_take_their_triangles_and_textures_from_the_budgets_while_held() {
    let cornell = procedural::cornell_box();
    let triangles = cornell.triangle_count() as u64;
    let registry = idle(&Limits {
        max_total_triangles: triangles * 3 / 2,
        ..limits(4)
    });
    let first = registry
        .insert(cornell.clone(), "t".into(), None, 0.0, None)
        .expect("fits");
    let Err(e) = registry.insert(cornell.clone(), "t".into(), None, 0.0, None) else {
        panic!("over the total");
    };
    assert_eq!(e.status, axum::http::StatusCode::PAYLOAD_TOO_LARGE);
    assert_eq!(e.body.error, "triangle_budget");
    assert!(
        e.body.message.contains("--max-total-triangles"),
        "{}",
        e.body.message
    );
    assert!(
        registry.detached(cornell.clone(), 0.0).is_err(),
        "uploads count too"
    );
    let id = first.id.clone();
    drop(first);
    registry.remove(&id, None).expect("removed");
    assert!(registry
        .insert(cornell, "t".into(), None, 0.0, None)
        .is_ok());

    let mut textured = procedural::cornell_box();
    textured.textures.push(crate::scene::Texture {
        name: "t".into(),
        width: 64,
        height: 64,
        rgba8: vec![255; 64 * 64 * 4],
    });
    let registry = idle(&Limits {
        max_scene_texture_bytes: 64 * 64 * 4,
        max_total_texture_bytes: 64 * 64 * 4,
        ..limits(4)
    });
    let held = registry.detached(textured.clone(), 0.0).expect("fits");
    let Err(e) = registry.detached(textured.clone(), 0.0) else {
        panic!("the total is held");
    };
    assert_eq!(e.body.error, "texture_budget");
    assert!(
        e.body.message.contains("--max-total-texture-bytes"),
        "{}",
        e.body.message
    );
    drop(held);
    assert!(registry.detached(textured, 0.0).is_ok());
}

#[test]
fn a_full_queue_refuses_new_work_until_it_drains() {
    let (registry, seen, go) = gated();
    let entry = registry
        .detached(procedural::cornell_box(), 0.0)
        .expect("fits");
    assert!(matches!(
        registry.precomputed(&entry, &params(1.0)),
        Now::Pending
    ));
    assert_eq!(seen.recv_timeout(WAIT).as_deref(), Ok(entry.id.as_str()));
    // The worker holds the first job; the queue takes MAX_QUEUED_JOBS more.
    for k in 0..MAX_QUEUED_JOBS {
        let p = params(2.0 + k as f32);
        assert!(
            matches!(registry.precomputed(&entry, &p), Now::Pending),
            "job {k}"
        );
    }
    let refused = params(100.0);
    assert!(matches!(registry.precomputed(&entry, &refused), Now::Busy));
    assert_eq!(
        state(&entry, &refused),
        None,
        "a refused job leaves no variant"
    );
    go.send(()).expect("worker alive");
    assert!(seen.recv_timeout(WAIT).is_ok());
    assert!(matches!(
        registry.precomputed(&entry, &refused),
        Now::Pending
    ));
    drop(go);
}

#[test]
fn the_queue_serves_short_jobs_first_and_a_long_one_once_it_has_waited_its_length() {
    let queue = JobQueue::default();
    let job = |estimated: f64, waited: f64| Job {
        scene: Weak::new(),
        key: params(estimated as f32),
        estimated,
        queued: Instant::now() - Duration::from_secs_f64(waited),
    };
    assert!(queue.push(job(500.0, 0.0)));
    assert!(queue.push(job(3.0, 0.0)));
    assert!(queue.push(job(20.0, 0.0)));
    let next = |max| queue.next(max).map(|j| j.estimated);
    assert_eq!(next(f64::INFINITY), Some(3.0));
    // The quick lane never takes a long job.
    assert!(queue.push(job(1.0, 0.0)));
    assert_eq!(next(QUICK_JOB_SECONDS), Some(1.0));
    assert_eq!(next(f64::INFINITY), Some(20.0));
    // A long job that has waited as long as it takes goes before a new short one.
    assert!(queue.push(job(600.0, 700.0)));
    assert!(queue.push(job(2.0, 0.0)));
    assert_eq!(next(f64::INFINITY), Some(600.0));
    queue.close();
    assert_eq!(next(f64::INFINITY), None, "closed");
}

#[test]
fn a_long_precomputation_does_not_hold_up_short_ones() {
    let (started_tx, started) = mpsc::channel();
    let (release, release_rx) = mpsc::channel::<()>();
    let release_rx = Mutex::new(release_rx);
    let registry = SceneRegistry::with_workers(&limits(4), Some(QUICK_JOB_SECONDS), {
        move |_, key, _| {
            let _ = started_tx.send(key.kind);
            if key.kind == crate::gi::surfels::SURFEL_LINKS {
                let _ = lock(&release_rx).recv();
            }
        }
    });
    let entry = registry
        .detached(procedural::cornell_box(), 0.0)
        .expect("fits");
    let surfels = GiParams::new(crate::gi::surfels::SURFELS)
        .with("surfel_count", 262_144)
        .with("surfel_links", 16);
    let long = entry
        .precompute_key(&surfels)
        .expect("within the budgets")
        .expect("surfels precompute");
    let mut cost = crate::gi::cost::Cost::default();
    (crate::gi::surfels::PRECOMPUTE.cost)(&long, &entry.facts, &mut cost);
    assert!(cost.seconds(1.0) > QUICK_JOB_SECONDS, "{cost:?}");
    assert!(matches!(registry.precomputed(&entry, &long), Now::Pending));
    assert_eq!(
        started.recv_timeout(WAIT),
        Ok(crate::gi::surfels::SURFEL_LINKS)
    );
    // The general worker is busy with it; the light caches run on the quick one.
    assert!(matches!(
        registry.precomputed(&entry, &params(1.0)),
        Now::Pending
    ));
    assert_eq!(
        started.recv_timeout(WAIT),
        Ok(lightcast_protocol::LIGHT_CACHES)
    );
    drop(release);
}

#[test]
fn jobs_of_scenes_gone_from_every_holder_are_skipped() {
    let (registry, seen, go) = gated();
    let kept = registry
        .detached(procedural::cornell_box(), 0.0)
        .expect("fits");
    registry.precomputed(&kept, &params(1.0));
    assert_eq!(seen.recv_timeout(WAIT).as_deref(), Ok(kept.id.as_str()));
    let dropped = registry
        .detached(procedural::cornell_box(), 0.0)
        .expect("fits");
    registry.precomputed(&dropped, &params(1.0));
    registry.precomputed(&kept, &params(2.0));
    drop(dropped);
    go.send(()).expect("worker alive");
    go.send(()).expect("worker alive");
    assert_eq!(seen.recv_timeout(WAIT).as_deref(), Ok(kept.id.as_str()));
    drop(go);
    assert!(seen.recv_timeout(Duration::from_millis(200)).is_err());
}

#[test]
fn a_panicking_precomputation_fails_its_variant_and_the_worker_goes_on() {
    let (done_tx, done) = mpsc::channel();
    let registry = SceneRegistry::with_workers(&limits(4), None, move |entry, p, _| {
        assert!(p != &params(1.0), "a bug in the precomputation");
        let _ = done_tx.send(entry.id.clone());
    });
    let entry = registry
        .detached(procedural::cornell_box(), 0.0)
        .expect("fits");
    registry.precomputed(&entry, &params(1.0));
    registry.precomputed(&entry, &params(2.0));
    // The jobs run cheapest first: the panic may come before or after the other job.
    match settled(&registry, &entry, &params(1.0)) {
        Now::Failed(e) => assert!(e.contains("internal error"), "{e}"),
        _ => panic!("the panicked variant must read as failed"),
    }
    assert_eq!(done.recv_timeout(WAIT).as_deref(), Ok(entry.id.as_str()));
    assert_eq!(state(&entry, &params(1.0)), Some(PrecomputeState::Failed));
    // The failed set gave its estimate back; the other still holds its own.
    let second = (crate::gi::lightskin::PRECOMPUTE.estimate)(&params(2.0), &entry.facts);
    assert_eq!(caches_used(&registry), second);
}

/// Waits until `key` of `entry` is ready or failed.
fn settled(registry: &SceneRegistry, entry: &Arc<SceneEntry>, key: &PrecomputeKey) -> Now {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        match registry.precomputed(entry, key) {
            Now::Pending | Now::Busy if Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(10))
            }
            now => return now,
        }
    }
}

#[test]
fn the_bvh_is_built_on_the_worker_and_listed_with_the_light_caches() {
    let store = tempfile::tempdir().expect("temp dir");
    let registry = SceneRegistry::new(Store::new(store.path()), &limits(4), None);
    let entry = registry
        .insert(procedural::cornell_box(), "t".into(), None, 0.0, None)
        .expect("fits");
    let reference = GiParams::new(crate::gi::reference::REFERENCE);
    let bvh = entry
        .precompute_key(&reference)
        .expect("valid")
        .expect("the reference needs its BVH");
    assert_eq!(bvh.kind, "bvh");
    let none = GiParams::new(crate::gi::none::NONE);
    assert_eq!(entry.precompute_key(&none).expect("valid"), None);
    let Now::Ready(data) = settled(&registry, &entry, &bvh) else {
        panic!("the BVH must build");
    };
    let built = data
        .downcast_ref::<crate::gi::common::bvh::SceneBvh>()
        .expect("a BVH");
    assert_eq!(
        built.triangles.len(),
        entry.scene.triangle_count(),
        "every triangle in the BVH"
    );
    let caches = key_for(&entry, 0.37).expect("fits").expect("brsm");
    assert!(matches!(settled(&registry, &entry, &caches), Now::Ready(_)));
    let info = entry.info();
    let kinds: Vec<_> = info.precomputed.iter().map(|p| p.kind.as_str()).collect();
    // The default light caches are queued when the scene is added, before anything asks.
    assert_eq!(kinds, ["light_caches", "bvh", "light_caches"], "{kinds:?}");
    let bvh_info = &info.precomputed[1];
    assert_eq!(bvh_info.state, PrecomputeState::Ready);
    assert_eq!(bvh_info.progress, Some(1.0));
    assert!(bvh_info.params.is_empty());
    // The BVH holds a copy of every triangle: counted against the triangle budget again.
    let triangles = entry.scene.triangle_count() as u64;
    assert_eq!(bvh_info.units, Some(triangles));
    assert_eq!(bvh_info.unit.as_deref(), Some("triangles"));
    assert_eq!(registry.budget().triangles.used(), 2 * triangles);
    assert_eq!(info.caches.len(), 2, "only light caches in the old list");
    assert_eq!(info.caches[1].cache_distance, 0.37);
    assert_eq!(info.caches[1].caches, info.precomputed[2].units);
    assert!(info.caches[1].caches.is_some_and(|n| n > 0));
}
