//! The live follower (`vltm live`) on a T3 stream that arrives in pieces: the input is one
//! byte `k` (the read sizes of the simulated pipe: 1 + (k + i·31) mod 97 bytes for read `i`,
//! some reads returning nothing first: an interrupted read), `n` (2 bytes, little endian),
//! `n` bytes of sidecar JSON, then the stream (a PTU header and records). Every row is
//! followed to the end of the stream or the first error; the rows handed out must have the
//! sidecar's size and come in order. (The `ptu` target's seeds fit, after one leading byte.)
#![no_main]

mod common;
use libfuzzer_sys::fuzz_target;
use std::io::{self, Read};
use std::path::Path;
use vltm::io::ptu::{Follower, Sidecar};

/// A pipe that hands out the bytes in pieces of varying size and is sometimes interrupted.
struct Pipe {
    data: Vec<u8>,
    pos: usize,
    k: usize,
    i: usize,
}

impl Read for Pipe {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.i += 1;
        if (self.k + self.i) % 7 == 0 {
            return Err(io::Error::from(io::ErrorKind::Interrupted));
        }
        let want = 1 + (self.k + self.i * 31) % 97;
        let n = want.min(buf.len()).min(self.data.len() - self.pos);
        buf[..n].copy_from_slice(&self.data[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
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
    let pipe = Pipe {
        data: stream.to_vec(),
        pos: 0,
        k,
        i: 0,
    };
    let Ok(mut f) = Follower::stream(Box::new(pipe), Path::new("<stdin>"), sidecar, side) else {
        return;
    };
    let per_row = f.geometry().spads_per_row() * f.geometry().nt;
    let mut next = 0;
    while let Ok(Some(r)) = f.next_row() {
        assert_eq!(r.index, next);
        assert_eq!(r.data.len(), per_row);
        next += 1;
    }
    assert!(next <= f.rows());
});
