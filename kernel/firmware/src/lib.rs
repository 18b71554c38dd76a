//! vltm-firmware: the fixture scan streamed through `vltm-kernel` on a Cortex-M, all state
//! in `static` memory. See README.md.
#![no_std]

pub mod fixed_pipeline;
pub mod fixture;
#[cfg(feature = "cycles")]
pub mod icount;
#[cfg(feature = "cycles")]
pub mod lookup_cycles;
pub mod lookup_pipeline;
pub mod pipeline;
#[cfg(feature = "state")]
pub mod state;

#[cfg(target_endian = "big")]
compile_error!(
    "scan.bin holds little-endian u16: read it with from_le_bytes on big-endian targets"
);

/// `include_bytes!` with 2-byte alignment, so that the counts can be read in place as `u16`.
#[repr(C, align(2))]
struct Aligned<B: ?Sized>(B);

/// `fixture/scan.bin` (16 KB), in flash.
static SCAN_BIN: &Aligned<[u8]> = &Aligned(*include_bytes!("../fixture/scan.bin"));

/// The fixture scan as `u16` counts, read in place from flash (no copy); `None` only if the
/// embedded file were misaligned or of odd length (it is neither).
pub fn scan_data() -> Option<&'static [u16]> {
    bytemuck::try_cast_slice(&SCAN_BIN.0).ok()
}
