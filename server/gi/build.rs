//! Validates every WGSL module with naga, so a shader error fails `cargo build` without a GPU
//! (as Vello's build script does).
//!
//! The modules are read from their declarations: every `ShaderSource { name: "…", files:
//! &[wgsl!("…"), …] }` in a `shaders.rs` of this crate or of `lightcast-passes` (the shared
//! passes' in `gpu/shaders.rs`, each method's in `<method>/shaders.rs`). The names validated are
//! written to `$OUT_DIR/validated_shaders.txt`; a test checks they are every module
//! `gi::all_shaders()` lists, so a declaration this scan misses fails it.

use std::path::{Path, PathBuf};

fn main() {
    // Read when the script runs, not baked in when it is compiled: a build script binary is
    // reused by checkouts that share a target directory.
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("set by Cargo"));
    validate_shaders(&manifest);
}

/// One declared module: its name and its files (relative to `shaders/`), in order.
struct Module {
    name: String,
    files: Vec<String>,
}

fn validate_shaders(manifest: &Path) {
    let shaders = manifest.join("../../shaders");
    println!("cargo:rerun-if-changed={}", shaders.display());
    let mut declarations = Vec::new();
    collect_shader_rs(&manifest.join("src"), &mut declarations);
    collect_shader_rs(&manifest.join("../passes/src"), &mut declarations);
    declarations.sort();
    let mut validated = Vec::new();
    let mut errors = Vec::new();
    for path in &declarations {
        println!("cargo:rerun-if-changed={}", path.display());
        let text = std::fs::read_to_string(path).expect("a shaders.rs is readable");
        for module in modules_of(&text) {
            let mut source = String::new();
            for file in &module.files {
                let path = shaders.join(file);
                println!("cargo:rerun-if-changed={}", path.display());
                match std::fs::read_to_string(&path) {
                    Ok(text) => source.push_str(&format!("// ---- {file}\n{text}\n")),
                    Err(e) => errors.push(format!("{}: {file}: {e}", module.name)),
                }
            }
            if let Err(e) = validate(&source) {
                errors.push(format!(
                    "WGSL module {} ({}):\n{e}",
                    module.name,
                    path.display()
                ));
            }
            validated.push(module.name);
        }
    }
    if !errors.is_empty() {
        panic!("invalid shaders:\n{}", errors.join("\n"));
    }
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    std::fs::write(out.join("validated_shaders.txt"), validated.join("\n"))
        .expect("OUT_DIR is writable");
}

/// Every `shaders.rs` under `dir`.
fn collect_shader_rs(dir: &Path, found: &mut Vec<PathBuf>) {
    println!("cargo:rerun-if-changed={}", dir.display());
    for entry in std::fs::read_dir(dir).expect("src/ is readable") {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            collect_shader_rs(&path, found);
        } else if path.file_name().is_some_and(|n| n == "shaders.rs") {
            found.push(path);
        }
    }
}

/// The modules a `shaders.rs` declares: each `= ShaderSource {` block's `name` and `wgsl!`
/// files up to its closing `};`.
fn modules_of(text: &str) -> Vec<Module> {
    let mut modules = Vec::new();
    let mut rest = text;
    while let Some(start) = rest.find("= ShaderSource {\n") {
        let block_start = &rest[start..];
        let end = block_start.find("\n};").unwrap_or(block_start.len());
        let block = &block_start[..end];
        rest = &block_start[end..];
        let Some(name) = quoted_after(block, "name: ") else {
            continue;
        };
        let files = block
            .match_indices("wgsl!(")
            .filter_map(|(i, _)| quoted_after(&block[i..], "wgsl!("))
            .collect();
        modules.push(Module { name, files });
    }
    modules
}

/// The string literal right after `key` in `text`.
fn quoted_after(text: &str, key: &str) -> Option<String> {
    let after = &text[text.find(key)? + key.len()..];
    let after = after.strip_prefix('"')?;
    Some(after[..after.find('"')?].to_string())
}

/// Parses and validates one module as the shader tests do (primitive indices allowed: the
/// G-buffer variant that uses them is created only where the adapter has them).
fn validate(source: &str) -> Result<(), String> {
    let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string(source))?;
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::PRIMITIVE_INDEX,
    )
    .validate(&module)
    .map_err(|e| e.emit_to_string(source))?;
    Ok(())
}
