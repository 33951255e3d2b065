//! Whether the target's instruction set has SMLAL, the signed 32 × 32 + 64-bit
//! multiply-accumulate a filter step is (`cfg(smlal)`, see `feature::mul_acc`): the Cortex-M
//! targets of ARMv7-M and ARMv8-M mainline. Everywhere else the step is written in Rust.

fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rustc-check-cfg=cfg(smlal)");
    let target = std::env::var("TARGET").unwrap_or_default();
    if ["thumbv7m-", "thumbv7em-", "thumbv8m.main-"]
        .iter()
        .any(|arch| target.starts_with(arch))
    {
        println!("cargo::rustc-cfg=smlal");
    }
}
