//! Links the `shakeflow` executable position-dependent on Linux (docs/benchmarks.md, "Per call").
//!
//! A position-independent executable carries ~300 000 relative relocations (every vtable and
//! static pointer of arrow, parquet, polars and clap) that the dynamic linker applies at each
//! start, touching and copying ~7 MB of pages: 5.3 ms of the 15 ms CPU a one-unit `stage` call
//! cost. Linked at a fixed address those pointers are resolved once, by the linker. Only the
//! binary changes (the library, tests and benches keep the default); macOS requires PIE.
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("linux") {
        println!("cargo:rustc-link-arg-bins=-no-pie");
    }
}
