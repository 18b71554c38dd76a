//! The live follower (`vltm live`) on a T3 stream that arrives in pieces. The input is one
//! byte `k`, `n` (2 bytes, little endian), `n` bytes of sidecar JSON, then the stream (a PTU
//! header and records; the `ptu` target's seeds fit, after one leading byte). `k` picks:
//!
//! * bit 0 — **a growing file** (`Follower::reader` with a path: the stream is also written
//!   to a file there, whose header the follower re-reads for a patched record count) or
//!   **a pipe**;
//! * the read sizes, 1 + (k + 31·i) mod 97 bytes for read `i`, some reads interrupted, and
//!   for a growing file some reads returning nothing yet (the file has not grown: the
//!   follower polls again);
//! * bit 1 — at the end of the bytes, a pipe closes (end of file) or **stops sending without
//!   closing** (the read reports the idle timeout, `TimedOut`, as the relay thread of
//!   `Follower::stream` does); a growing file always stops growing (the same timeout);
//! * bits 3–4 — rows passed over first without binning (`Follower::skip_rows`, a resumed run).
//!
//! Every row is followed to the end of the stream or the first error; the rows handed out
//! must have the sidecar's size and come in order from the first row not skipped.
#![no_main]

mod common;
use libfuzzer_sys::fuzz_target;
use std::io::{self, Read};
use std::path::{Path, PathBuf};
use std::time::Duration;
use vltm::io::ptu::{FollowOptions, Follower, Sidecar};

/// A stream that hands out the bytes in pieces of varying size, sometimes interrupted, and
/// for a growing file sometimes with nothing new yet.
struct Pipe {
    data: Vec<u8>,
    pos: usize,
    k: usize,
    i: usize,
    growing: bool,
    stalls: bool,
}

impl Read for Pipe {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.i += 1;
        if (self.k + self.i) % 7 == 0 {
            return Err(io::Error::from(io::ErrorKind::Interrupted));
        }
        if self.pos == self.data.len() {
            return if self.stalls {
                Err(io::Error::from(io::ErrorKind::TimedOut))
            } else {
                Ok(0)
            };
        }
        if self.growing && (self.k + self.i) % 5 == 0 {
            return Ok(0);
        }
        let want = 1 + (self.k + self.i * 31) % 97;
        let n = want.min(buf.len()).min(self.data.len() - self.pos);
        buf[..n].copy_from_slice(&self.data[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
}

fn scratch() -> PathBuf {
    std::env::temp_dir().join(format!("vltm-fuzz-follow-{}.ptu", std::process::id()))
}

fuzz_target!(|data: &[u8]| {
    common::init();
    if data.len() < 3 {
        return;
    }
    let k = usize::from(data[0]);
    let data = &data[1..];
    let n = usize::from(u16::from_le_bytes([data[0], data[1]])).min(data.len() - 2);
    let (json, stream) = data[2..].split_at(n);
    let Ok(json) = std::str::from_utf8(json) else {
        return;
    };
    let side = Path::new("fuzz.json");
    let Ok(sidecar) = Sidecar::from_json_str(json, side) else {
        return;
    };
    let growing = k & 1 == 1;
    let file = growing.then(scratch);
    if let Some(f) = &file
        && std::fs::write(f, stream).is_err()
    {
        return;
    }
    let pipe = Pipe {
        data: stream.to_vec(),
        pos: 0,
        k,
        i: 0,
        growing,
        stalls: growing || k & 2 == 2,
    };
    let opts = FollowOptions {
        idle_timeout: Duration::from_secs(10),
        poll: Duration::ZERO,
    };
    let Ok(mut f) = Follower::reader(
        Box::new(pipe),
        file.as_deref(),
        Path::new("<stdin>"),
        sidecar,
        side,
        opts,
    ) else {
        return;
    };
    let skip = (k >> 3) & 3;
    f.skip_rows(skip);
    let per_row = f.geometry().spads_per_row() * f.geometry().nt;
    let mut next = skip.min(f.rows());
    while let Ok(Some(r)) = f.next_row() {
        assert_eq!(r.index, next);
        assert_eq!(r.data.len(), per_row);
        next += 1;
    }
    assert!(next <= f.rows());
});
