//! vltm's own `.npz` capture format: written compressed or stored, read whole, and streamed
//! row by row from a stored (uncompressed) archive.
//!
//! Keys of vltm's `.npz` capture format (names follow y-tal's HDF5 fields).
//!
//! | key | dtype, shape | meaning |
//! |---|---|---|
//! | `H` | f32 `(Lx, Ly, Sx, Sy, Nt)`, or `(Lx, Ly, Nt)` if confocal | histograms, time last |
//! | `laser_grid_xyz` | f32 `(Lx, Ly, 3)` | laser spots |
//! | `sensor_grid_xyz` | f32 `(Sx, Sy, 3)` | SPAD spots |
//! | `laser_xyz`, `sensor_xyz` | f64 `(3,)` | device positions |
//! | `delta_t`, `t_start` | f64 `()` | bin width, time of bin 0 (m) |
//! | `t_accounts_first_and_last_bounces`, `confocal` | u8 `()` | flags |
//! | `laser_grid_normals`, `sensor_grid_normals` (optional) | f32 `(Lx, Ly, 3)`, `(Sx, Sy, 3)` | relay-surface normals at the spots (absent: +z; written only when some normal is not +z) |
//!
//! `confocal = 1` means one histogram per row: a **paired** scan, row `l` lit at
//! `laser_grid_xyz[l]` and seen at `sensor_grid_xyz[l]` (the two grids have one shape; a
//! confocal capture when they are equal). vltm writes paired captures in this layout.
//!
//! **Per-histogram paired form** (what a user writes with numpy for a galvo-scanned or
//! arbitrary scan; recognised by `laser_xyz` of shape `(K, 3)` and no `laser_grid_xyz`):
//!
//! | key | dtype, shape | meaning |
//! |---|---|---|
//! | `H` | f32 `(K, Nt)` | histogram `k`, time last |
//! | `laser_xyz`, `sensor_xyz` | f32 or f64 `(K, 3)` | the laser and SPAD spot of histogram `k` (m) |
//! | `delta_t`, `t_start` | f64 `()` | bin width, time of bin 0 (m) |
//! | `laser_normals`, `sensor_normals` (optional) | f32 or f64 `(K, 3)` | relay-surface normals at the spots (absent: +z): checked (finite, non-zero length), used by `--compensate-laser` and `--weights cos` |
//! | `laser_origin`, `sensor_origin` (optional) | f64 `(3,)` | device positions (default the origin) |
//! | `t_accounts_first_and_last_bounces` (optional) | u8 `()` | device legs in the time axis (needs both origins) |
//!
//! Every field is checked before anything is read into the capture: lists of different
//! lengths, NaN or infinite points and zero-length normals are one-line errors naming the key.

mod read;
mod stream;
mod write;

pub use read::read;
pub use stream::{NpzStream, open_stream};
pub use write::{stage, write, write_with};

#[cfg(test)]
mod tests;
