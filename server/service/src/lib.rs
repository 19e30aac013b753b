//! The network service (`lightcast-server serve`): scenes shared by all sessions, one render
//! loop owning the GPU, an encoder pool, and the HTTP/WebSocket API in [`http`].
//!
//! ```text
//! client JSON ─▶ session state ─▶ render loop (round robin, paced) ─▶ encoder pool
//!                                                   ─▶ latest-frame slot ─▶ WebSocket
//! ```

// Paths as when the layers were modules of one crate: `crate::service::…`, `crate::gi::…`.
use crate as service;
use lightcast_gi as gi;
use lightcast_passes::{gpu, passes};
use lightcast_render::{debug_views, offline, quality, renderer};
use lightcast_scene as scene;

pub mod budget;
pub mod config;
pub mod cost;
pub mod defaults;
pub mod encode;
pub mod error;
pub mod http;
pub mod ids;
pub mod listen;
pub mod metrics;
pub mod params;
pub mod render_loop;
pub mod routing;
pub mod scene_store;
pub mod scenes;
pub mod sessions;
pub mod sync;
pub mod video;

use crate::gi::precompute::Store;
use crate::gpu::{GpuContext, GpuError};
use crate::scene::Scene;
pub use config::ServeArgs;
use lightcast_protocol::DEFAULT_SCENE_ID;
use std::net::SocketAddr;
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

/// Why the service could not start.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error(transparent)]
    Config(#[from] config::ConfigError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("default scene '{spec}': {error}")]
    DefaultScene {
        spec: String,
        error: crate::scene::OpenError,
    },
    #[error("cannot listen on {addr}: {error}")]
    Bind {
        addr: SocketAddr,
        error: std::io::Error,
    },
    #[error("starting the encoder threads: {0}")]
    Encoder(#[from] rayon::ThreadPoolBuildError),
    #[error("the server task failed: {0}")]
    Task(String),
    #[error(transparent)]
    SceneStore(#[from] scene_store::StoreError),
    #[error(transparent)]
    NoVisibilityBuffer(#[from] crate::renderer::NoVisibilityBuffer),
}

/// A running service.
pub struct Service {
    /// The address it listens on (the real port when 0 was asked for).
    pub addr: SocketAddr,
    pub adapter: String,
    shutdown: tokio::sync::watch::Sender<bool>,
    server: tokio::task::JoinHandle<()>,
    render_tx: mpsc::Sender<render_loop::Command>,
    render_thread: std::thread::JoinHandle<()>,
    sessions: Arc<sessions::SessionRegistry>,
    scenes: Arc<scenes::SceneRegistry>,
}

impl Service {
    /// Opens the GPU, loads the default scene, starts the render loop and listens.
    /// `log` receives progress lines meant for people.
    pub async fn start(args: &ServeArgs, log: &(dyn Fn(&str) + Sync)) -> Result<Self, ServeError> {
        let connections = args.limits.connections();
        let tokens = args.tokens()?;
        let mut limits = args.limits.limits(tokens.len())?;
        let backend = args.backend;
        let ctx = tokio::task::spawn_blocking(move || GpuContext::new(backend))
            .await
            .map_err(|e| ServeError::Task(e.to_string()))??;
        let adapter = crate::gpu::context::AdapterSummary(&ctx.info).to_string();
        log(&format!("adapter: {adapter}"));
        let is_cpu = ctx.info.device_type == wgpu::DeviceType::Cpu;
        if args.visibility_buffer == crate::renderer::VisibilityBuffer::On && !ctx.primitive_index {
            return Err(crate::renderer::NoVisibilityBuffer.into());
        }
        limits.adapter_speed = args.limits.adapter_speed.resolve(is_cpu);
        limits.max_frame_seconds = args.limits.max_frame_cost.resolve(is_cpu);
        log(&format!(
            "request cost: at most {} s of estimated adapter work per frame \
             (--max-frame-cost) and {} s per one-shot render (--max-request-cost), the \
             adapter taken as {}× the reference lavapipe (--adapter-speed); precomputations \
             at most {} s (--max-precompute-cost)",
            limits.max_frame_seconds,
            limits.max_request_seconds,
            limits.adapter_speed,
            limits.max_precompute_seconds
        ));
        // A validation error is a bug in a pass, not something to take every session down
        // for: log it and count it instead of wgpu's default panic.
        ctx.device.on_uncaptured_error(Arc::new(|e: wgpu::Error| {
            tracing::error!("GPU error: {e}");
            ::metrics::counter!(metrics::ERRORS, "kind" => "gpu").increment(1);
        }));
        metrics::handle();

        let store = Store {
            dir: args.cache_dir.clone().unwrap_or_else(Store::default_dir),
            max_bytes: Some(args.cache_max_bytes),
        };
        let scenes = scenes::SceneRegistry::new(store, &limits, Some(ctx.clone()));
        let spec = args.default_scene.clone();
        let started = Instant::now();
        let scene = tokio::task::spawn_blocking(move || Scene::open(&spec))
            .await
            .map_err(|e| ServeError::Task(e.to_string()))?
            .map_err(|error| ServeError::DefaultScene {
                spec: args.default_scene.clone(),
                error,
            })?;
        let load_ms = started.elapsed().as_secs_f64() * 1e3;
        log(&format!(
            "default scene: {} ({} triangles, {load_ms:.0} ms)",
            args.default_scene,
            scene.triangle_count()
        ));
        let source = if args.default_scene.starts_with("procedural:") {
            args.default_scene.clone()
        } else {
            "file".to_string()
        };
        scenes
            .insert(scene, source, Some(DEFAULT_SCENE_ID), load_ms, None)
            .map_err(|e| ServeError::Task(e.body.message))?;

        let routing = args
            .routing()
            .map_err(|e| ServeError::Task(e.to_string()))?;
        if let Some(r) = &routing {
            log(&format!(
                "replica {}: session ids carry this name, signed with the routing key",
                r.replica()
            ));
        }
        let sessions = Arc::new(sessions::SessionRegistry::new(&limits, routing));
        ::metrics::gauge!(metrics::SESSION_CAPACITY).set(f64::from(limits.max_sessions));
        let video = video::EncoderKind::select(args.encoder);
        log(&format!(
            "h264 streams: {} ({})",
            video.name(),
            if video.hardware() {
                "hardware"
            } else {
                "software"
            }
        ));
        let encoder = Arc::new(encode::EncodePool::new(
            args.encode_threads
                .unwrap_or_else(encode::EncodePool::default_threads),
            video,
        )?);
        let timing_source = if ctx.timestamps {
            "gpu_timestamps"
        } else {
            "cpu_wall_clock"
        };
        let options = render_loop::LoopOptions {
            reuse: !args.no_pass_reuse,
            frames_in_flight: args
                .frames_in_flight
                .map_or(if is_cpu { 2 } else { 3 }, usize::from),
            visibility_buffer: args.visibility_buffer,
        };
        let thin = match options.visibility_buffer {
            crate::renderer::VisibilityBuffer::Auto if is_cpu => "off (auto: a CPU adapter)",
            crate::renderer::VisibilityBuffer::Auto => {
                "on where the device has triangle ids (auto)"
            }
            crate::renderer::VisibilityBuffer::On => "on",
            crate::renderer::VisibilityBuffer::Off => "off",
        };
        log(&format!(
            "render loop: up to {} frames in flight (--frames-in-flight), visibility buffers \
             {thin} (--visibility-buffer), pass reuse and sharing {} (--no-pass-reuse)",
            options.frames_in_flight,
            if options.reuse { "on" } else { "off" }
        ));
        let (render_tx, render_thread) = render_loop::spawn(
            ctx.clone(),
            Arc::clone(&scenes),
            Arc::clone(&sessions),
            encoder,
            options,
        );
        let listener = tokio::net::TcpListener::bind(args.listen)
            .await
            .map_err(|error| ServeError::Bind {
                addr: args.listen,
                error,
            })?;
        let addr = listener.local_addr().map_err(|error| ServeError::Bind {
            addr: args.listen,
            error,
        })?;
        let (shutdown, shutdown_rx) = tokio::sync::watch::channel(false);
        let defaults = defaults::Defaults::choose(
            args.defaults,
            &ctx.info.name,
            ctx.info.device_type == wgpu::DeviceType::Cpu,
        );
        log(&defaults.summary());
        let scene_store = match &args.scene_store {
            Some(dir) => {
                let store = scene_store::SceneStore::open(dir)?;
                log(&format!(
                    "scene store: {} (uploaded scenes are shared with every replica using it)",
                    dir.display()
                ));
                Some(store)
            }
            None => None,
        };
        let state = Arc::new(http::AppState::new(
            Arc::clone(&scenes),
            scene_store,
            Arc::clone(&sessions),
            render_tx.clone(),
            limits,
            tokens,
            &ctx,
            args.allow_cpu_adapter,
            defaults,
            timing_source.to_string(),
            video,
            shutdown_rx.clone(),
        ));
        if state.auth_enabled() {
            log("auth: bearer tokens required");
        }
        if state.limits.session_idle_secs > 0 {
            tokio::spawn(reap_idle_sessions(
                Arc::clone(&sessions),
                Duration::from_secs(state.limits.session_idle_secs),
                shutdown_rx.clone(),
            ));
        }
        let app = http::router(state);
        let server = tokio::spawn(listen::serve(listener, app, connections, shutdown_rx));
        log(&format!("listening on http://{addr}"));
        Ok(Self {
            addr,
            adapter,
            shutdown,
            server,
            render_tx,
            render_thread,
            sessions,
            scenes,
        })
    }

    /// Stops: every open session gets a `closing` event and a close frame, the listener
    /// stops, the render loop finishes its frame and exits. Light caches being written are
    /// renamed into place atomically, so nothing is left half-written.
    pub async fn shutdown(self) -> Result<(), ServeError> {
        for s in self.sessions.all() {
            s.close("server shutting down");
        }
        self.shutdown.send_replace(true);
        let served = self.server.await;
        let _ = self.render_tx.send(render_loop::Command::Stop);
        let thread = self.render_thread;
        tokio::task::spawn_blocking(move || thread.join())
            .await
            .map_err(|e| ServeError::Task(e.to_string()))?
            .map_err(|_| ServeError::Task("the render loop panicked".into()))?;
        let scenes = self.scenes;
        tokio::task::spawn_blocking(move || scenes.stop_workers())
            .await
            .map_err(|e| ServeError::Task(e.to_string()))?;
        served.map_err(|e| ServeError::Task(e.to_string()))
    }
}

/// Ends sessions that had no stream attached for `timeout` (clients that vanished without
/// deleting them), until the server shuts down.
async fn reap_idle_sessions(
    sessions: Arc<sessions::SessionRegistry>,
    timeout: Duration,
    mut shutdown: tokio::sync::watch::Receiver<bool>,
) {
    let period = (timeout / 4).clamp(Duration::from_millis(100), Duration::from_secs(30));
    let mut ticks = tokio::time::interval(period);
    loop {
        tokio::select! {
            _ = ticks.tick() => {}
            _ = shutdown.wait_for(|s| *s) => return,
        }
        for s in sessions.remove_idle(timeout, Instant::now()) {
            tracing::info!(session = %s.id, "ending a session with no stream for {} s", timeout.as_secs());
            s.close(&format!(
                "session idle: no stream for {} s",
                timeout.as_secs()
            ));
        }
    }
}

/// Resolves when the process gets SIGINT (Ctrl-C) or SIGTERM.
pub async fn termination_signal() {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        let mut term =
            match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                Ok(s) => s,
                Err(e) => {
                    tracing::warn!("cannot listen for SIGTERM: {e}");
                    let _ = ctrl_c.await;
                    return;
                }
            };
        tokio::select! {
            _ = ctrl_c => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    let _ = ctrl_c.await;
}
