//! Gathers every GI method's renderer tests (`../gi/src/<method>/gpu_tests.rs`) into the
//! `methods` test target (`tests/methods.rs`), one module per method, so a method's tests stay
//! in its folder and adding one needs no line here.

use std::path::PathBuf;

fn main() {
    // Read when the script runs, not baked in when it is compiled: a build script binary is
    // reused by checkouts that share a target directory.
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("set by Cargo"));
    let methods = manifest.join("../gi/src");
    println!("cargo:rerun-if-changed={}", methods.display());
    let mut modules = Vec::new();
    for entry in std::fs::read_dir(&methods).expect("the GI crate's sources") {
        let dir = entry.expect("a directory entry").path();
        let tests = dir.join("gpu_tests.rs");
        println!("cargo:rerun-if-changed={}", tests.display());
        if tests.is_file() {
            let name = dir
                .file_name()
                .and_then(|n| n.to_str())
                .expect("a method folder has a UTF-8 name")
                .to_string();
            let path = tests.canonicalize().expect("the tests' path");
            modules.push(format!(
                "#[path = {:?}]\nmod {name};\n",
                path.display().to_string()
            ));
        }
    }
    modules.sort();
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    std::fs::write(out.join("method_gpu_tests.rs"), modules.concat())
        .expect("the generated module list is written");
}
