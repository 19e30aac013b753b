//! The server's integration tests, in one test binary (one link of the GPU stack instead of
//! one per file): GPU passes against CPU references, light caches, and the binary run as a
//! user would.

mod caches;
mod frame_memory;
mod fuzz;
mod gpu_brdf;
mod gpu_brsm_sampling;
mod gpu_cache_lighting;
mod gpu_clustered;
mod gpu_clustered_visibility;
mod gpu_direct_light;
mod gpu_emitters;
mod gpu_environment;
mod gpu_glossy_senders;
mod gpu_indirect_resolution;
mod gpu_moving_nodes;
mod gpu_pass_reuse;
mod gpu_reference;
mod gpu_scenes;
mod gpu_stream_bench;
mod gpu_surfel_links;
mod gpu_surfels;
mod gpu_visibility_buffer;
mod gpu_yuv420;
mod render_cli;
mod scale_invariance;
mod serve_cli;
mod setup_script;
mod support;
