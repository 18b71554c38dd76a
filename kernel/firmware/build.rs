//! Picks memory.x by target and adds the linker scripts to the bins only (never to other
//! crates): `-Tlink.x` (cortex-m-rt) for all, `-Tdefmt.x` for the defmt bin only.
use std::{env, fs, path::PathBuf};

fn main() {
    let target = env::var("TARGET").unwrap_or_default();
    // VLTM_FW_BOARD=mps2-an386 links an ARMv6-M build for the mps2-an386 (its Cortex-M4 runs
    // the M0's instruction stream): the fixed-point instruction counts need more than the
    // microbit's 16 KB of RAM.
    let an386 = env::var("VLTM_FW_BOARD").is_ok_and(|b| b == "mps2-an386");
    let mem: &[u8] = if target.starts_with("thumbv6m") && !an386 {
        include_bytes!("memory/microbit.x")
    } else {
        include_bytes!("memory/mps2-an386.x")
    };
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    fs::write(out.join("memory.x"), mem).expect("write memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    if env::var_os("CARGO_FEATURE_DEFMT").is_some() {
        println!("cargo:rustc-link-arg-bin=vltm-firmware-defmt=-Tdefmt.x");
    }
    println!("cargo:rerun-if-changed=memory");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=VLTM_FW_BOARD");
}
