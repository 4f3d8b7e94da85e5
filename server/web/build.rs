//! Names the compiler in `gridscada_build_info` (`/metrics`). The commit
//! comes from `GRIDSCADA_COMMIT` at build time, where the builder sets it.

fn main() {
    println!("cargo:rerun-if-env-changed=GRIDSCADA_COMMIT");
    println!("cargo:rerun-if-changed=build.rs");
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let version = std::process::Command::new(rustc)
        .arg("--version")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|v| v.trim().to_string())
        .unwrap_or_default();
    println!("cargo:rustc-env=GRIDSCADA_RUSTC={version}");
}
