//! Each GI method's tests that render frames, kept in the method's folder
//! (`server/gi/src/<method>/gpu_tests.rs`) and gathered here by the build script: they need
//! the renderer, which the GI crate's own tests cannot use (it is built on that crate).

include!(concat!(env!("OUT_DIR"), "/method_gpu_tests.rs"));
