//! Unit tests of the PTU reader and writer.

use super::binning::Counts;
use super::decode::*;
use super::header::*;
use super::sidecar::*;
use super::source::*;
use super::write::*;
use crate::aperture::{Aperture, DEFAULT_LASER_ORIGIN, DEFAULT_SENSOR_ORIGIN};
use crate::error::{Error, Result};
use crate::io::capture::{Capture, Geometry, RowSource};
use std::io::{Cursor, Write};
use std::path::Path;
use vltm_kernel::Point;

// ----- helpers ---------------------------------------------------------------------------

fn field(e: &Error) -> &str {
    match e {
        Error::Format { field, .. } => field,
        other => panic!("expected a format error, got: {other}"),
    }
}

fn found(e: &Error) -> &str {
    match e {
        Error::Format { found, .. } => found,
        other => panic!("expected a format error, got: {other}"),
    }
}

fn pt3(channel: u8, dtime: u16, nsync: u16) -> u32 {
    (u32::from(channel & 0x0F) << 28) | (u32::from(dtime & 0x0FFF) << 16) | u32::from(nsync)
}

/// Header fields of a test file; `omit` leaves one tag out.
#[derive(Clone)]
struct H {
    rec_type: i64,
    bits: i64,
    n: i64,
    global: f64,
    res: f64,
    omit: &'static str,
}

impl H {
    fn new(rec_type: u32, n: usize) -> Self {
        Self {
            rec_type: i64::from(rec_type),
            bits: 32,
            n: n as i64,
            global: 50e-9,
            res: 4e-12,
            omit: "",
        }
    }
}

fn header(h: &H) -> Vec<u8> {
    let mut v = Vec::new();
    v.extend_from_slice(&MAGIC);
    v.extend_from_slice(b"1.0.00\0\0");
    let mut tw = TagWriter { w: &mut v };
    let mut int = |name: &str, x: i64| {
        if name != h.omit {
            tw.int(name, x).unwrap();
        }
    };
    int("TTResultFormat_TTTRRecType", h.rec_type);
    int("TTResultFormat_BitsPerRecord", h.bits);
    int("TTResult_NumberOfRecords", h.n);
    let mut tw = TagWriter { w: &mut v };
    for (name, x) in [
        ("MeasDesc_GlobalResolution", h.global),
        ("MeasDesc_Resolution", h.res),
    ] {
        if name != h.omit {
            tw.float(name, x).unwrap();
        }
    }
    tw.raw("Header_End", -1, tag_type::EMPTY8, [0; 8]).unwrap();
    v
}

fn file(h: &H, records: &[u32]) -> Vec<u8> {
    let mut v = header(h);
    for r in records {
        v.extend_from_slice(&r.to_le_bytes());
    }
    v
}

fn hh2(records: &[u32]) -> Vec<u8> {
    file(&H::new(0x0101_0304, records.len()), records)
}

fn read_header(bytes: &[u8]) -> Result<Header> {
    Header::read(&mut Cursor::new(bytes), Path::new("t.ptu"))
}

fn events(bytes: &[u8]) -> Result<Vec<Event>> {
    let mut c = Cursor::new(bytes);
    let h = Header::read(&mut c, Path::new("t.ptu"))?;
    Records::new(c, &h, "t.ptu").collect()
}

fn sidecar(rows: usize, ks: usize, nt: usize) -> Sidecar {
    Sidecar {
        rows: None,
        row_marker: 1,
        lasers: Aperture::grid([rows, 1], [1.0, 0.0], [0.0, 0.0]),
        spads: Some(Aperture::points(
            (0..ks).map(|s| [0.1 * s as f64, 0.0, 0.0]).collect(),
        )),
        confocal: false,
        channels: None,
        unmapped_channels: Unmapped::Error,
        nt,
        t0: 0.5,
        bin_width: None,
        rebin: 1,
        first_dtime: 0,
        laser_origin: DEFAULT_LASER_ORIGIN,
        sensor_origin: DEFAULT_SENSOR_ORIGIN,
        legs_in_time: false,
    }
}

fn source(bytes: Vec<u8>, sc: Sidecar) -> Result<PtuSource<Cursor<Vec<u8>>>> {
    PtuSource::from_reader(Cursor::new(bytes), "t.ptu", sc, Path::new("t.json"))
}

fn all_rows(src: &mut PtuSource<Cursor<Vec<u8>>>) -> Result<Vec<Vec<f32>>> {
    let mut rows = Vec::new();
    for l in 0..src.rows() {
        let mut row = Vec::new();
        src.read_row(l, &mut row)?;
        rows.push(row);
    }
    Ok(rows)
}

/// 3 lasers × 2 SPADs × 50 bins of small counts, some fractional (to test rounding).
fn tiny(confocal: bool) -> Capture {
    let lasers: Vec<Point> = (0..3).map(|l| [0.1 * l as f32 - 0.1, 0.05, 0.0]).collect();
    let spads: Vec<Point> = if confocal {
        lasers.clone()
    } else {
        vec![[0.3, -0.2, 0.0], [0.35, -0.2, 0.0]]
    };
    let ks = if confocal { 1 } else { 2 };
    let nt = 50;
    let data = (0..3 * ks * nt)
        .map(|i| {
            let base = ((i * 7 + i / 13) % 5) as f32;
            match i % 11 {
                0 => base + 0.4,
                5 => base + 0.6,
                _ => base,
            }
        })
        .collect();
    let geometry = Geometry {
        laser_shape: [3, 1],
        spad_shape: if confocal { [3, 1] } else { [2, 1] },
        lasers,
        spads,
        laser_origin: [-0.5, 0.0, 0.25],
        sensor_origin: [-0.4, 0.1, 0.25],
        legs_in_time: true,
        confocal,
        nt,
        dt: 0.0123,
        t0: 0.75,
        normals: Default::default(),
    };
    Capture::new(geometry, data, Path::new("tiny")).unwrap()
}

fn rounded(c: &Capture) -> Vec<f32> {
    c.data.iter().map(|v| v.round()).collect()
}

fn written(c: &Capture, opts: &T3WriteOptions) -> (Vec<u8>, T3Written) {
    let mut bytes = Vec::new();
    let w = write_t3_to(c, &mut bytes, opts, Path::new("mem.ptu")).unwrap();
    (bytes, w)
}

// ----- header ----------------------------------------------------------------------------

/// A header with every tag type, indexed tags and image tags; returns (bytes, header length).
fn hand_built(records: &[u32]) -> (Vec<u8>, usize) {
    let mut v = Vec::new();
    v.extend_from_slice(b"PQTTTR\0\0");
    v.extend_from_slice(b"1.0.00\0\0");
    let mut tw = TagWriter { w: &mut v };
    tw.raw("Fancy_Empty", -1, tag_type::EMPTY8, [0; 8]).unwrap();
    tw.raw("Fancy_Bool", -1, tag_type::BOOL8, 1i64.to_le_bytes())
        .unwrap();
    tw.raw("Fancy_Int", -1, tag_type::INT8, (-5i64).to_le_bytes())
        .unwrap();
    tw.raw("Fancy_Bits", -1, tag_type::BITSET64, 0xF0u64.to_le_bytes())
        .unwrap();
    tw.raw("Fancy_Color", -1, tag_type::COLOR8, 0xFF00u64.to_le_bytes())
        .unwrap();
    tw.raw("Fancy_Float", -1, tag_type::FLOAT8, 2.5f64.to_le_bytes())
        .unwrap();
    tw.raw(
        "File_CreatingTime",
        -1,
        tag_type::DATETIME,
        45000.5f64.to_le_bytes(),
    )
    .unwrap();
    tw.raw(
        "Fancy_Array",
        -1,
        tag_type::FLOAT8_ARRAY,
        24i64.to_le_bytes(),
    )
    .unwrap();
    for x in [1.0f64, 2.0, 3.0] {
        tw.w.write_all(&x.to_le_bytes()).unwrap();
    }
    tw.string("File_Comment", "hello PTU").unwrap();
    let wide: Vec<u8> = "Wide ü\0\0"
        .encode_utf16()
        .flat_map(u16::to_le_bytes)
        .collect();
    tw.raw(
        "Fancy_Wide",
        -1,
        tag_type::WIDE_STRING,
        (wide.len() as i64).to_le_bytes(),
    )
    .unwrap();
    tw.w.write_all(&wide).unwrap();
    tw.raw("Fancy_Blob", -1, tag_type::BINARY_BLOB, 5i64.to_le_bytes())
        .unwrap();
    tw.w.write_all(&[9, 8, 7, 6, 5]).unwrap();
    tw.raw("HW_Markers", 0, tag_type::BOOL8, 1i64.to_le_bytes())
        .unwrap();
    tw.raw("HW_Markers", 1, tag_type::BOOL8, 0i64.to_le_bytes())
        .unwrap();
    tw.int("ImgHdr_LineStart", 1).unwrap();
    tw.int("ImgHdr_PixX", 64).unwrap();
    tw.int("TTResultFormat_TTTRRecType", 0x0101_0304).unwrap();
    tw.int("TTResultFormat_BitsPerRecord", 32).unwrap();
    tw.int("TTResult_NumberOfRecords", records.len() as i64)
        .unwrap();
    tw.float("MeasDesc_GlobalResolution", 25e-9).unwrap();
    tw.float("MeasDesc_Resolution", 1e-12).unwrap();
    tw.raw("Header_End", -1, tag_type::EMPTY8, [0; 8]).unwrap();
    let len = v.len();
    for r in records {
        v.extend_from_slice(&r.to_le_bytes());
    }
    (v, len)
}

#[test]
fn ptu_header_hand_built() {
    let recs = [ht3(true, 1, 0, 3), ht3(false, 2, 77, 9)];
    let (bytes, len) = hand_built(&recs);
    let h = read_header(&bytes).unwrap();
    assert_eq!(h.version, "1.0.00");
    assert_eq!(h.data_offset, len as u64);
    assert_eq!(h.record_type, RecordType::HydraHarpV2T3);
    assert_eq!(h.record_type_code, 0x0101_0304);
    assert_eq!((h.num_records, h.bits_per_record), (2, 32));
    assert_eq!((h.global_resolution, h.resolution), (25e-9, 1e-12));
    assert_eq!(
        h.image,
        ImageTags {
            line_start: Some(1),
            pix_x: Some(64),
            ..ImageTags::default()
        }
    );
    assert_eq!(h.get("Fancy_Empty"), Some(&TagValue::Empty));
    assert_eq!(h.get("Fancy_Bool"), Some(&TagValue::Bool(true)));
    assert_eq!(h.get("Fancy_Int"), Some(&TagValue::Int(-5)));
    assert_eq!(h.get("Fancy_Bits"), Some(&TagValue::BitSet(0xF0)));
    assert_eq!(h.get("Fancy_Color"), Some(&TagValue::Color(0xFF00)));
    assert_eq!(h.get("Fancy_Float"), Some(&TagValue::Float(2.5)));
    assert_eq!(
        h.get("File_CreatingTime"),
        Some(&TagValue::DateTime(45000.5))
    );
    assert_eq!(
        h.get("Fancy_Array"),
        Some(&TagValue::Float8Array { len: 24 })
    );
    assert_eq!(
        h.get("File_Comment"),
        Some(&TagValue::AnsiString("hello PTU".into()))
    );
    assert_eq!(
        h.get("Fancy_Wide"),
        Some(&TagValue::WideString("Wide ü".into()))
    );
    assert_eq!(h.get("Fancy_Blob"), Some(&TagValue::Blob { len: 5 }));
    assert_eq!(h.get_indexed("HW_Markers", 1), Some(&TagValue::Bool(false)));
    assert_eq!(h.tags.last().unwrap().name, "Header_End");
    assert_eq!(h.get("Nope"), None);
    // The records follow the header.
    assert_eq!(
        events(&bytes).unwrap(),
        vec![
            Event::Marker { bits: 1, sync: 3 },
            Event::Photon {
                channel: 2,
                dtime: 77,
                sync: 9
            }
        ]
    );
}

#[test]
fn ptu_header_latin1_and_long_string() {
    let mut v = header(&H::new(0x0101_0304, 0));
    // Insert two tags before the required ones: rebuild by hand.
    v.truncate(16);
    let mut tw = TagWriter { w: &mut v };
    tw.raw("Latin", -1, tag_type::ANSI_STRING, 8i64.to_le_bytes())
        .unwrap();
    tw.w.write_all(b"caf\xe9\0\0\0\0").unwrap();
    let long = MAX_STRING + 8;
    tw.raw(
        "Long",
        -1,
        tag_type::ANSI_STRING,
        (long as i64).to_le_bytes(),
    )
    .unwrap();
    tw.w.write_all(&vec![b'x'; long as usize]).unwrap();
    let rest = header(&H::new(0x0101_0304, 0));
    v.extend_from_slice(&rest[16..]);
    let h = read_header(&v).unwrap();
    assert_eq!(h.get("Latin"), Some(&TagValue::AnsiString("café".into())));
    assert_eq!(
        h.get("Long"),
        Some(&TagValue::LongString {
            type_code: tag_type::ANSI_STRING,
            len: long
        })
    );
    assert_eq!(h.data_offset, v.len() as u64);
}

// ----- record decoding -------------------------------------------------------------------

fn photon(channel: u8, dtime: u16, sync: u64) -> Decoded {
    Decoded::Event(Event::Photon {
        channel,
        dtime,
        sync,
    })
}

fn marker(bits: u8, sync: u64) -> Decoded {
    Decoded::Event(Event::Marker { bits, sync })
}

#[test]
fn ptu_record_bits() {
    // Independent of `ht3`: special:1 channel:6 dtime:15 nsync:10 from the MSB.
    assert_eq!(ht3(false, 5, 1234, 1000), 0x0A13_4BE8);
    assert_eq!(ht3(true, 63, 0, 3), 0xFE00_0003);
    assert_eq!(ht3(true, 2, 0, 7), 0x8400_0007);
    assert_eq!(pt3(15, 0, 0), 0xF000_0000);
    assert_eq!(pt3(2, 0xABC, 0x1234), 0x2ABC_1234);
    // Byte order: records are little-endian in the file.
    let bytes = hh2(&[0x0A13_4BE8]);
    assert_eq!(&bytes[bytes.len() - 4..], &[0xE8, 0x4B, 0x13, 0x0A]);
    assert_eq!(
        events(&bytes).unwrap(),
        vec![Event::Photon {
            channel: 5,
            dtime: 1234,
            sync: 1000
        }]
    );
}

/// The same records under V1 and V2 overflow semantics.
fn overflow_sequence() -> [u32; 7] {
    [
        ht3(false, 5, 1234, 1000),
        ht3(true, 63, 0, 3), // V1: +1024, V2: +3·1024
        ht3(false, 0, 32767, 5),
        ht3(true, 63, 0, 0), // +1024 in both
        ht3(true, 2, 0, 7),  // marker 2
        ht3(true, 0, 0, 9),  // reserved
        ht3(true, 40, 3, 9), // reserved
    ]
}

#[test]
fn ptu_decode_hydraharp_v1_v2() {
    let seq = overflow_sequence();
    let mut v1 = Decoder::new(RecordType::HydraHarpV1T3);
    let got: Vec<Decoded> = seq.iter().map(|&r| v1.decode(r)).collect();
    assert_eq!(
        got,
        vec![
            photon(5, 1234, 1000),
            Decoded::Overflow { syncs: 1024 },
            photon(0, 32767, 1029),
            Decoded::Overflow { syncs: 1024 },
            marker(2, 2055),
            Decoded::Reserved,
            Decoded::Reserved,
        ]
    );
    assert_eq!(v1.overflow_syncs(), 2048);
    for code in [
        0x0101_0304,
        0x0001_0305,
        0x0001_0306,
        0x0101_0305,
        0x0101_0306,
        0x0001_0307,
    ] {
        let kind = RecordType::from_code(code).unwrap();
        let mut d = Decoder::new(kind);
        let got: Vec<Decoded> = seq.iter().map(|&r| d.decode(r)).collect();
        assert_eq!(
            got,
            vec![
                photon(5, 1234, 1000),
                Decoded::Overflow { syncs: 3072 },
                photon(0, 32767, 3077),
                Decoded::Overflow { syncs: 1024 },
                marker(2, 4103),
                Decoded::Reserved,
                Decoded::Reserved,
            ],
            "{}",
            kind.name()
        );
    }
    // Marker bits 1..15 all decode; 1023 overflows at once.
    let mut d = Decoder::new(RecordType::MultiHarpT3);
    for b in 1..=15u8 {
        assert_eq!(d.decode(ht3(true, b, 0, 1)), marker(b, 1));
    }
    assert_eq!(
        d.decode(ht3(true, 63, 0, 1023)),
        Decoded::Overflow { syncs: 1023 * 1024 }
    );
    assert_eq!(
        d.decode(ht3(false, 63, 1, 1023)),
        photon(63, 1, 1024 * 1024 - 1)
    );
}

#[test]
fn ptu_decode_picoharp() {
    let mut d = Decoder::new(RecordType::PicoHarpT3);
    assert_eq!(d.decode(pt3(1, 4000, 65535)), photon(0, 4000, 65535));
    assert_eq!(d.decode(pt3(15, 0, 17)), Decoded::Overflow { syncs: 65536 });
    assert_eq!(d.decode(pt3(4, 4095, 1)), photon(3, 4095, 65537));
    assert_eq!(d.decode(pt3(15, 4, 7)), marker(4, 65543));
    assert_eq!(d.decode(pt3(15, 0x013, 7)), marker(3, 65543));
    assert_eq!(d.decode(pt3(15, 0x010, 7)), Decoded::Reserved);
    assert_eq!(
        d.decode(pt3(0, 5, 5)),
        Decoded::IllegalChannel { channel: 0 }
    );
    assert_eq!(
        d.decode(pt3(5, 5, 5)),
        Decoded::IllegalChannel { channel: 5 }
    );
    assert_eq!(d.overflow_syncs(), 65536);
}

/// PicoQuant's `Read_PTU.py` logic, transcribed literally (binary-string slicing), as an
/// independent cross-check: lines "CHN ch sync dtime" / "MAR bits sync".
fn read_ptu_py(records: &[u32], pico: bool, version: u32) -> Vec<String> {
    let mut out = Vec::new();
    let mut ofl: u64 = 0;
    let bits = |s: &str| u64::from_str_radix(s, 2).unwrap();
    for &r in records {
        let rd = format!("{r:032b}");
        if pico {
            let (channel, dtime, nsync) = (bits(&rd[0..4]), bits(&rd[4..16]), bits(&rd[16..32]));
            if channel == 0xF {
                if dtime == 0 {
                    ofl += 65536;
                } else {
                    out.push(format!("MAR {dtime} {}", ofl + nsync));
                }
            } else {
                out.push(format!("CHN {channel} {} {dtime}", ofl + nsync));
            }
        } else {
            let special = bits(&rd[0..1]);
            let channel = bits(&rd[1..7]);
            let dtime = bits(&rd[7..22]);
            let nsync = bits(&rd[22..32]);
            if special == 1 {
                if channel == 0x3F {
                    if nsync == 0 || version == 1 {
                        ofl += 1024;
                    } else {
                        ofl += 1024 * nsync;
                    }
                }
                if (1..=15).contains(&channel) {
                    out.push(format!("MAR {channel} {}", ofl + nsync));
                }
            } else {
                out.push(format!("CHN {channel} {} {dtime}", ofl + nsync));
            }
        }
    }
    out
}

#[test]
fn ptu_decode_matches_read_ptu_py() {
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut rand = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 32) as u32
    };
    for (code, pico, version) in [
        (0x0001_0304u32, false, 1),
        (0x0101_0304, false, 2),
        (0x0001_0305, false, 2),
        (0x0001_0307, false, 2),
        (0x0001_0303, true, 0),
    ] {
        let records: Vec<u32> = (0..5000)
            .map(|_| {
                let r = rand();
                if pico {
                    // Legal channels 1..4 and specials with markers in the low nibble.
                    match r % 6 {
                        0 => pt3(15, 0, r as u16),
                        1 => pt3(15, ((r >> 16) % 15 + 1) as u16, r as u16),
                        _ => pt3((r % 4 + 1) as u8, (r >> 8) as u16, (r >> 12) as u16),
                    }
                } else {
                    match r % 7 {
                        0 => ht3(true, 63, 0, (r >> 10) as u16 % 4),
                        1 => ht3(true, (r >> 8) as u8, 0, (r >> 16) as u16),
                        _ => r & 0x7FFF_FFFF,
                    }
                }
            })
            .collect();
        let bytes = file(&H::new(code, records.len()), &records);
        let ours: Vec<String> = events(&bytes)
            .unwrap()
            .into_iter()
            .map(|e| match e {
                Event::Photon {
                    channel,
                    dtime,
                    sync,
                } => format!(
                    "CHN {} {sync} {dtime}",
                    u32::from(channel) + u32::from(pico)
                ),
                Event::Marker { bits, sync } => format!("MAR {bits} {sync}"),
            })
            .collect();
        let theirs = read_ptu_py(&records, pico, version);
        assert_eq!(ours.len(), theirs.len(), "0x{code:08X}");
        assert_eq!(ours, theirs, "0x{code:08X}");
        assert!(ours.iter().any(|s| s.starts_with("MAR")));
    }
}

// ----- round trip ------------------------------------------------------------------------

#[test]
fn ptu_round_trip_in_memory() {
    let c = tiny(false);
    let (bytes, w) = written(&c, &T3WriteOptions::default());
    let photons: f32 = rounded(&c).iter().sum();
    assert_eq!(w.photons, photons as u64);
    assert_eq!(w.markers, 3);
    assert_eq!(w.records, w.photons + w.markers + w.overflow_records);
    assert!(w.overflow_records >= 2, "{w:?}");
    let h = read_header(&bytes).unwrap();
    assert_eq!(h.record_type, RecordType::HydraHarpV2T3);
    assert_eq!(h.num_records, w.records);
    assert_eq!(h.resolution, c.geometry.dt / SPEED_OF_LIGHT);
    assert_eq!(h.global_resolution, 50e-9);
    assert_eq!(bytes.len() as u64, h.data_offset + 4 * w.records);

    let mut src = source(bytes.clone(), w.sidecar.clone()).unwrap();
    let back = collect(&mut src, Path::new("mem.ptu")).unwrap();
    assert_eq!(back.geometry, c.geometry);
    assert_eq!(back.data, rounded(&c));
    let n = src.counts();
    assert_eq!(n.binned, w.photons);
    assert_eq!(n.overflow_records, w.overflow_records);
    assert_eq!(
        (
            n.before_first_marker,
            n.outside_window,
            n.unmapped,
            n.skipped_rows
        ),
        (0, 0, 0, 0)
    );

    // Multi-overflow records (V2) are there: 5000 syncs between rows.
    let mut c2 = Cursor::new(&bytes[..]);
    let h = Header::read(&mut c2, Path::new("mem.ptu")).unwrap();
    let mut recs = Records::new(c2, &h, "mem.ptu");
    let mut markers = Vec::new();
    while let Some(e) = recs.next_event().unwrap() {
        if let Event::Marker { bits, sync } = e {
            assert_eq!(bits, 1);
            markers.push(sync);
        }
    }
    let per_row: Vec<u64> = (0..3)
        .map(|l| c.row(l).iter().map(|v| v.round() as u64).sum())
        .collect();
    assert_eq!(
        markers,
        vec![0, per_row[0] + 5001, per_row[0] + per_row[1] + 10002]
    );
    assert_eq!(recs.decoder().overflow_syncs() % 1024, 0);
}

#[test]
fn ptu_round_trip_options_and_confocal() {
    for (confocal, opts) in [
        (
            false,
            T3WriteOptions {
                syncs_per_photon: 700,
                syncs_between_rows: 0,
                row_marker: 3,
                ..T3WriteOptions::default()
            },
        ),
        (
            true,
            T3WriteOptions {
                syncs_per_photon: 0,
                syncs_between_rows: 3_000_000,
                ..T3WriteOptions::default()
            },
        ),
    ] {
        let c = tiny(confocal);
        let (bytes, w) = written(&c, &opts);
        assert_eq!(w.sidecar.row_marker, opts.row_marker);
        assert!(w.overflow_records > 0);
        let mut src = source(bytes, w.sidecar).unwrap();
        let back = collect(&mut src, Path::new("mem.ptu")).unwrap();
        assert_eq!(back.geometry, c.geometry);
        assert_eq!(back.data, rounded(&c));
    }
}

#[test]
fn ptu_round_trip_files() {
    let dir = std::env::temp_dir().join(format!("vltm-ptu-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ptu = dir.join("tiny.ptu");
    let c = tiny(false);
    let w = write_t3(&c, &ptu, &T3WriteOptions::default()).unwrap();
    let sc_path = w.sidecar_path.clone().unwrap();
    assert_eq!(sc_path, dir.join("tiny.json"));
    assert_eq!(Sidecar::load(&sc_path).unwrap(), w.sidecar);

    let back = read_all(&ptu, &sc_path).unwrap();
    assert_eq!(back.data, rounded(&c));
    let (g, h) = (&back.geometry, &c.geometry);
    assert_eq!((&g.lasers, &g.spads, g.nt), (&h.lasers, &h.spads, h.nt));
    assert_eq!((g.laser_shape, g.spad_shape), (h.laser_shape, h.spad_shape));
    assert_eq!((g.confocal, g.legs_in_time), (h.confocal, h.legs_in_time));
    // JSON floats: equal up to the parser's last bit.
    assert!((g.dt - h.dt).abs() <= 1e-15 * h.dt && (g.t0 - h.t0).abs() <= 1e-15 * h.t0);
    for (a, b) in [
        (g.laser_origin, h.laser_origin),
        (g.sensor_origin, h.sensor_origin),
    ] {
        assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-15));
    }

    // The event stream of the file.
    let (hd, recs) = open(&ptu).unwrap();
    assert_eq!(hd.num_records, w.records);
    let ev: Vec<Event> = recs.collect::<Result<_>>().unwrap();
    assert_eq!(ev.len() as u64, w.photons + w.markers);

    // Rows in any order: forward skips, backward rewinds.
    let mut src = PtuSource::open(&ptu, &sc_path).unwrap();
    let mut row = Vec::new();
    for l in [2, 0, 1, 1, 0, 2, 2, 1, 2] {
        src.read_row(l, &mut row).unwrap();
        assert_eq!(row, back.row(l), "row {l}");
    }
    let mut src = PtuSource::open(&ptu, &sc_path).unwrap();
    src.read_row(2, &mut row).unwrap();
    let per_row = |l: usize| c.row(l).iter().map(|v| v.round() as u64).sum::<u64>();
    assert_eq!(src.counts().skipped_rows, per_row(0) + per_row(1));
    assert_eq!(src.counts().binned, per_row(2));
    src.read_row(0, &mut row).unwrap(); // rewinds: counts restart
    assert_eq!(src.counts().binned, per_row(0));
    assert_eq!(src.counts().skipped_rows, 0);

    // The sidecar must not overwrite the PTU file.
    let e = write_t3(&c, dir.join("x.json"), &T3WriteOptions::default()).unwrap_err();
    assert!(matches!(e, Error::Argument { .. }), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn ptu_rebin_window_and_channel_map() {
    let c = tiny(false);
    let (bytes, w) = written(&c, &T3WriteOptions::default());
    let r = rounded(&c);
    let (first, rebin, nt) = (10usize, 3usize, 12usize);
    let sc = Sidecar {
        first_dtime: first as u32,
        rebin: rebin as u32,
        nt,
        bin_width: None,
        channels: Some(vec![1, 0]), // SPAD 0 on channel 1, SPAD 1 on channel 0
        ..w.sidecar.clone()
    };
    let mut src = source(bytes, sc).unwrap();
    let width = src.header().resolution * SPEED_OF_LIGHT;
    let g = src.geometry().clone();
    assert_eq!(g.nt, nt);
    assert_eq!(g.dt, 3.0 * width);
    assert_eq!(g.t0, c.geometry.t0 + 11.0 * width);
    let rows = all_rows(&mut src).unwrap();
    let mut kept = 0.0;
    for (l, row) in rows.iter().enumerate() {
        for s in 0..2 {
            let ch = 1 - s;
            for n in 0..nt {
                let want: f32 = (0..rebin)
                    .map(|j| r[(l * 2 + ch) * 50 + first + n * rebin + j])
                    .sum();
                assert_eq!(row[s * nt + n], want, "l {l} s {s} n {n}");
                kept += want;
            }
        }
    }
    let n = src.counts();
    assert_eq!(n.binned, kept as u64);
    assert_eq!(n.binned + n.outside_window, w.photons);
    assert!(n.outside_window > 0);
}

#[test]
fn ptu_rows_markers_and_drops() {
    // photon, photon, M1, photon, M2 (other marker), M1|M2, photon ch 3, photon
    let recs = [
        ht3(false, 0, 1, 1),
        ht3(false, 1, 2, 2),
        ht3(true, 1, 0, 3),
        ht3(false, 1, 3, 4),
        ht3(true, 2, 0, 5),
        ht3(true, 3, 0, 6),
        ht3(false, 3, 4, 7),
        ht3(false, 0, 9, 8),
        ht3(true, 0, 0, 8), // reserved
    ];
    let mut sc = sidecar(2, 2, 8);
    sc.unmapped_channels = Unmapped::Drop;
    let mut src = source(hh2(&recs), sc.clone()).unwrap();
    let rows = all_rows(&mut src).unwrap();
    let mut want0 = vec![0.0; 16];
    want0[8 + 3] = 1.0;
    assert_eq!(rows, vec![want0, vec![0.0; 16]]);
    let n = src.counts();
    assert_eq!(n.before_first_marker, 2);
    assert_eq!(n.other_markers, 1);
    assert_eq!(n.unmapped, 1);
    assert_eq!(n.outside_window, 1); // dtime 9 ≥ nt = 8
    assert_eq!(n.reserved_records, 1);
    assert_eq!(n.binned, 1);

    // The same with unmapped channels an error.
    sc.unmapped_channels = Unmapped::Error;
    let mut src = source(hh2(&recs), sc).unwrap();
    let e = all_rows(&mut src).unwrap_err();
    assert_eq!(field(&e), "channels");
    assert!(found(&e).contains("channel 3 at record 6"), "{e}");

    // Out-of-range rows are an argument error, not a panic.
    let mut src = source(hh2(&recs), sidecar(2, 2, 8)).unwrap();
    assert!(matches!(
        src.read_row(2, &mut Vec::new()),
        Err(Error::Argument { .. })
    ));
}

/// The follower bins as the offline reader does (one binner): the same rows and counts, and
/// the same channel error, the follower's naming the byte position as well.
#[test]
fn follower_bins_as_the_source_does() {
    // The records of `ptu_rows_markers_and_drops`: drops before the first marker, an other
    // marker, an unmapped channel (3), a dtime outside the window, a reserved record.
    let recs = [
        ht3(false, 0, 1, 1),
        ht3(false, 1, 2, 2),
        ht3(true, 1, 0, 3),
        ht3(false, 1, 3, 4),
        ht3(true, 2, 0, 5),
        ht3(true, 3, 0, 6),
        ht3(false, 3, 4, 7),
        ht3(false, 0, 9, 8),
        ht3(true, 0, 0, 8),
    ];
    let follow = |sc: Sidecar| -> Result<(Vec<Vec<f32>>, Counts)> {
        let mut f = super::Follower::reader(
            Box::new(Cursor::new(hh2(&recs))),
            None,
            Path::new("t.ptu"),
            sc,
            Path::new("t.json"),
            super::FollowOptions::default(),
        )?;
        let mut rows = Vec::new();
        while let Some(r) = f.next_row()? {
            assert_eq!(r.photons, r.data.iter().sum::<f32>() as u64);
            rows.push(r.data);
        }
        Ok((rows, f.counts()))
    };
    let mut sc = sidecar(2, 2, 8);
    sc.unmapped_channels = Unmapped::Drop;
    let mut src = source(hh2(&recs), sc.clone()).unwrap();
    let rows = all_rows(&mut src).unwrap();
    let (followed, counts) = follow(sc.clone()).unwrap();
    assert_eq!(followed, rows);
    assert_eq!(counts, src.counts());
    assert_eq!(
        (counts.binned, counts.unmapped, counts.outside_window),
        (1, 1, 1)
    );

    sc.unmapped_channels = Unmapped::Error;
    let offline = all_rows(&mut source(hh2(&recs), sc.clone()).unwrap()).unwrap_err();
    let live = follow(sc).unwrap_err();
    assert_eq!(field(&live), field(&offline));
    let bytes = hh2(&recs);
    let at = bytes.len() - 4 * (recs.len() - 6); // record 6 starts here
    assert_eq!(
        found(&live),
        format!("{} (byte {at})", found(&offline)),
        "{live}"
    );
    let expected = |e: &Error| match e {
        Error::Format { expected, .. } => expected.clone(),
        other => panic!("expected a format error, got: {other}"),
    };
    assert_eq!(expected(&live), expected(&offline));
    assert!(expected(&live).contains("channels [0, 1]"), "{live}");
}

#[test]
fn ptu_picoharp_rows() {
    let recs = [
        pt3(15, 1, 0),  // marker 1: row 0
        pt3(1, 3, 10),  // channel 0, bin 3
        pt3(15, 0, 0),  // overflow
        pt3(2, 1, 10),  // channel 1, bin 1
        pt3(15, 2, 11), // marker 2: ignored
        pt3(15, 1, 12), // row 1
        pt3(2, 2, 13),  // channel 1, bin 2
    ];
    let bytes = file(&H::new(0x0001_0303, recs.len()), &recs);
    let mut src = source(bytes, sidecar(2, 2, 4)).unwrap();
    assert_eq!(src.header().record_type, RecordType::PicoHarpT3);
    let rows = all_rows(&mut src).unwrap();
    assert_eq!(
        rows,
        vec![
            vec![0., 0., 0., 1., 0., 1., 0., 0.],
            vec![0., 0., 0., 0., 0., 0., 1., 0.]
        ]
    );
    assert_eq!(src.counts().overflow_records, 1);
    assert_eq!(src.counts().other_markers, 1);
    // Default bin width: MeasDesc_Resolution·c.
    assert_eq!(src.geometry().dt, 4e-12 * SPEED_OF_LIGHT);
    // An illegal PicoHarp channel is an error.
    let bytes = file(&H::new(0x0001_0303, 2), &[pt3(15, 1, 0), pt3(7, 1, 1)]);
    let e = all_rows(&mut source(bytes, sidecar(1, 2, 4)).unwrap()).unwrap_err();
    assert_eq!(field(&e), "records");
    assert!(found(&e).contains("channel 7"), "{e}");
}

// ----- malformed input -------------------------------------------------------------------

#[test]
fn ptu_bad_magic() {
    let mut bytes = hh2(&[]);
    bytes[5] = b'X';
    assert_eq!(field(&read_header(&bytes).unwrap_err()), "magic");
    let e = read_header(b"\x89PNG\r\n\x1a\n0000000000000000").unwrap_err();
    assert_eq!(field(&e), "magic");
}

#[test]
fn ptu_truncated_header_every_length() {
    let (bytes, len) = hand_built(&[ht3(true, 1, 0, 0)]);
    for cut in 0..len {
        let e = read_header(&bytes[..cut]).unwrap_err();
        assert_eq!(field(&e), "header", "cut at {cut}: {e}");
        assert!(
            found(&e).contains(&format!("byte {cut}")),
            "cut at {cut}: {e}"
        );
    }
    assert!(read_header(&bytes[..len]).is_ok());
    // The written files too.
    let (bytes, _) = written(&tiny(false), &T3WriteOptions::default());
    let len = read_header(&bytes).unwrap().data_offset as usize;
    for cut in 0..len {
        assert_eq!(field(&read_header(&bytes[..cut]).unwrap_err()), "header");
    }
}

#[test]
fn ptu_unknown_tag_type_and_bad_lengths() {
    let mut v = Vec::new();
    v.extend_from_slice(&MAGIC);
    v.extend_from_slice(b"1.0.00\0\0");
    let mut tw = TagWriter { w: &mut v };
    tw.raw("Weird_Tag", -1, 0x1234_5678, [0; 8]).unwrap();
    let e = read_header(&v).unwrap_err();
    assert_eq!(field(&e), "Weird_Tag");
    assert!(found(&e).contains("0x12345678"), "{e}");

    for ty in [
        tag_type::ANSI_STRING,
        tag_type::WIDE_STRING,
        tag_type::FLOAT8_ARRAY,
        tag_type::BINARY_BLOB,
    ] {
        let mut v = v[..16].to_vec();
        let mut tw = TagWriter { w: &mut v };
        tw.raw("Neg_Len", -1, ty, (-8i64).to_le_bytes()).unwrap();
        assert_eq!(field(&read_header(&v).unwrap_err()), "Neg_Len");
        // A length past the end of the file is a truncated header.
        let mut v = v[..16].to_vec();
        let mut tw = TagWriter { w: &mut v };
        tw.raw("Huge_Len", -1, ty, i64::MAX.to_le_bytes()).unwrap();
        assert_eq!(field(&read_header(&v).unwrap_err()), "header");
    }
}

#[test]
fn ptu_bad_required_tags() {
    let ok = H::new(0x0101_0304, 0);
    assert!(read_header(&header(&ok)).is_ok());
    let check = |h: H, want_field: &str, want_found: &str| {
        let e = read_header(&header(&h)).unwrap_err();
        assert_eq!(field(&e), want_field, "{e}");
        assert!(found(&e).contains(want_found), "{e}");
    };
    // Unknown and T2 record types.
    for (code, what) in [
        (0x0001_0204i64, "HydraHarp V1 T2"),
        (0x0101_0204, "T2 mode"),
        (0x0001_0203, "PicoHarp T2"),
        (0x0000_DEAD, "0x0000DEAD"),
        (-1, "0xFFFFFFFFFFFFFFFF"),
    ] {
        check(
            H {
                rec_type: code,
                ..ok.clone()
            },
            "TTResultFormat_TTTRRecType",
            what,
        );
    }
    for bits in [16, 64, 0] {
        check(
            H { bits, ..ok.clone() },
            "TTResultFormat_BitsPerRecord",
            &bits.to_string(),
        );
    }
    check(
        H {
            n: -3,
            ..ok.clone()
        },
        "TTResult_NumberOfRecords",
        "-3",
    );
    for tag in [
        "TTResultFormat_TTTRRecType",
        "TTResultFormat_BitsPerRecord",
        "TTResult_NumberOfRecords",
        "MeasDesc_GlobalResolution",
        "MeasDesc_Resolution",
    ] {
        check(
            H {
                omit: tag,
                ..ok.clone()
            },
            tag,
            "no such tag",
        );
    }
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -1e-12, 0.0] {
        check(
            H {
                res: bad,
                ..ok.clone()
            },
            "MeasDesc_Resolution",
            "",
        );
        check(
            H {
                global: bad,
                ..ok.clone()
            },
            "MeasDesc_GlobalResolution",
            "",
        );
    }
    // A mistyped tag.
    let mut v = header(&H {
        omit: "MeasDesc_Resolution",
        ..ok.clone()
    });
    let end = v.len() - 48;
    v.truncate(end);
    let mut tw = TagWriter { w: &mut v };
    tw.int("MeasDesc_Resolution", 4).unwrap();
    tw.raw("Header_End", -1, tag_type::EMPTY8, [0; 8]).unwrap();
    let e = read_header(&v).unwrap_err();
    assert_eq!(field(&e), "MeasDesc_Resolution");
    assert!(found(&e).contains("Int8"), "{e}");
}

#[test]
fn ptu_truncated_and_overlong_records() {
    let c = tiny(false);
    let (bytes, w) = written(&c, &T3WriteOptions::default());
    for cut in 1..=4 {
        let short = bytes[..bytes.len() - cut].to_vec();
        let e = events(&short).unwrap_err();
        assert_eq!(field(&e), "records", "cut {cut}");
        let partial = format!("partial record of {} bytes", 4 - cut);
        assert_eq!(found(&e).contains(&partial), cut < 4, "{e}");
        let e = collect(
            &mut source(short, w.sidecar.clone()).unwrap(),
            Path::new("t"),
        )
        .unwrap_err();
        assert_eq!(field(&e), "records");
    }
    let mut long = bytes.clone();
    long.extend_from_slice(&[0, 0]);
    let e = events(&long).unwrap_err();
    assert_eq!(field(&e), "records");
    assert!(found(&e).contains("more data"), "{e}");
    // After an error the stream ends.
    let mut c2 = Cursor::new(&bytes[..bytes.len() - 2]);
    let h = Header::read(&mut c2, Path::new("t")).unwrap();
    let mut recs = Records::new(c2, &h, "t");
    assert!(recs.by_ref().any(|e| e.is_err()));
    assert!(recs.next().is_none());
}

#[test]
fn ptu_marker_count_mismatch() {
    let c = tiny(false);
    let (bytes, w) = written(&c, &T3WriteOptions::default());
    let with_lasers = |k: usize| Sidecar {
        rows: Some(k),
        lasers: Aperture::points((0..k).map(|l| [0.1 * l as f64, 0.0, 0.0]).collect()),
        ..w.sidecar.clone()
    };
    // Fewer markers (3) than rows (4).
    let mut src = source(bytes.clone(), with_lasers(4)).unwrap();
    let e = collect(&mut src, Path::new("t")).unwrap_err();
    assert_eq!(field(&e), "markers");
    assert!(found(&e).contains('3'), "{e}");
    // Asking directly for the missing row.
    let mut src = source(bytes.clone(), with_lasers(5)).unwrap();
    let e = src.read_row(4, &mut Vec::new()).unwrap_err();
    assert_eq!(field(&e), "markers");
    // More markers (3) than rows (2).
    let mut src = source(bytes.clone(), with_lasers(2)).unwrap();
    let e = collect(&mut src, Path::new("t")).unwrap_err();
    assert_eq!(field(&e), "markers");
    assert!(found(&e).contains("extra row marker"), "{e}");
    // A different marker input: no row markers at all.
    let sc = Sidecar {
        row_marker: 2,
        ..w.sidecar.clone()
    };
    let e = collect(&mut source(bytes.clone(), sc).unwrap(), Path::new("t")).unwrap_err();
    assert_eq!(field(&e), "markers");
    assert!(found(&e).contains('0'), "{e}");
    // A file with no records at all.
    let e = collect(&mut source(hh2(&[]), w.sidecar).unwrap(), Path::new("t")).unwrap_err();
    assert_eq!(field(&e), "markers");
}

#[test]
fn ptu_bad_sidecars() {
    let bytes = hh2(&[ht3(true, 1, 0, 0)]);
    let check = |sc: Sidecar, want: &str| {
        let e = source(bytes.clone(), sc).unwrap_err();
        assert_eq!(field(&e), want, "{e}");
    };
    let ok = sidecar(1, 2, 8);
    assert!(source(bytes.clone(), ok.clone()).is_ok());
    for m in [0, 5, 16] {
        check(
            Sidecar {
                row_marker: m,
                ..ok.clone()
            },
            "row_marker",
        );
    }
    check(
        Sidecar {
            rows: Some(2),
            ..ok.clone()
        },
        "rows",
    );
    check(
        Sidecar {
            channels: Some(vec![0]),
            ..ok.clone()
        },
        "channels",
    );
    check(
        Sidecar {
            channels: Some(vec![1, 1]),
            ..ok.clone()
        },
        "channels",
    );
    check(
        Sidecar {
            channels: Some(vec![0, 64]),
            ..ok.clone()
        },
        "channels",
    );
    for w in [f64::NAN, -0.01, 0.0, f64::INFINITY] {
        check(
            Sidecar {
                bin_width: Some(w),
                ..ok.clone()
            },
            "bin_width",
        );
    }
    check(
        Sidecar {
            t0: f64::NAN,
            ..ok.clone()
        },
        "t0",
    );
    check(
        Sidecar {
            nt: 0,
            ..ok.clone()
        },
        "nt",
    );
    check(
        Sidecar {
            rebin: 0,
            ..ok.clone()
        },
        "rebin",
    );
    check(
        Sidecar {
            spads: None,
            ..ok.clone()
        },
        "spads",
    );
    check(
        Sidecar {
            lasers: Aperture::grid([0, 1], [1.0, 1.0], [0.0, 0.0]),
            ..ok.clone()
        },
        "lasers",
    );
    check(
        Sidecar {
            spads: Some(Aperture::points(vec![[f64::NAN, 0.0, 0.0]])),
            channels: Some(vec![0]),
            ..ok.clone()
        },
        "spads",
    );
    check(
        Sidecar {
            confocal: true,
            ..ok.clone()
        },
        "spads",
    );
    check(
        Sidecar {
            laser_origin: [0.0, f64::NAN, 0.0],
            ..ok.clone()
        },
        "laser_origin",
    );
    // Confocal without spads is fine: one histogram per row.
    let sc = Sidecar {
        confocal: true,
        spads: None,
        ..ok.clone()
    };
    let src = source(bytes.clone(), sc).unwrap();
    assert!(src.geometry().confocal);
    assert_eq!(src.geometry().spads_per_row(), 1);

    // JSON-level errors.
    let json = ok.to_json();
    assert_eq!(Sidecar::from_json_str(&json, "s.json").unwrap(), ok);
    let bad = json.replacen('{', "{\"colour\": 1,", 1);
    let e = Sidecar::from_json_str(&bad, "s.json").unwrap_err();
    assert_eq!(field(&e), "sidecar");
    assert!(found(&e).contains("colour"), "{e}");
    let e =
        Sidecar::from_json_str(r#"{"lasers": {"grid": [1, 1]}, "nt": 5}"#, "s.json").unwrap_err();
    assert_eq!(field(&e), "sidecar");
    assert!(found(&e).contains("t0"), "{e}");
    let e = Sidecar::from_json_str("{", "s.json").unwrap_err();
    assert_eq!(field(&e), "sidecar");
    let minimal = r#"{"lasers": {"grid": [1, 1]}, "confocal": true, "nt": 5, "t0": 0.5}"#;
    let s = Sidecar::from_json_str(minimal, "s.json").unwrap();
    assert_eq!((s.row_marker, s.rebin, s.first_dtime), (1, 1, 0));
    assert_eq!(s.unmapped_channels, Unmapped::Error);
    let e = Sidecar::load("/nonexistent/vltm/s.json").unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e}");
}

#[test]
fn ptu_writer_rejects_bad_captures() {
    let mut c = tiny(false);
    for bad in [f32::NAN, f32::INFINITY, -1.0, 5e9] {
        c.data[7] = bad;
        let e =
            write_t3_to(&c, Vec::new(), &T3WriteOptions::default(), Path::new("w")).unwrap_err();
        assert_eq!(field(&e), "H", "{bad}");
    }
    c.data[7] = -0.4; // rounds to (−)0 photons: accepted
    assert!(write_t3_to(&c, Vec::new(), &T3WriteOptions::default(), Path::new("w")).is_ok());
    for opts in [
        T3WriteOptions {
            row_marker: 0,
            ..T3WriteOptions::default()
        },
        T3WriteOptions {
            row_marker: 5,
            ..T3WriteOptions::default()
        },
        T3WriteOptions {
            sync_period: f64::NAN,
            ..T3WriteOptions::default()
        },
        T3WriteOptions {
            sync_period: 0.0,
            ..T3WriteOptions::default()
        },
    ] {
        let e = write_t3_to(&c, Vec::new(), &opts, Path::new("w")).unwrap_err();
        assert!(matches!(e, Error::Argument { .. }), "{e}");
    }
    let mut big = tiny(false);
    big.geometry.spads = vec![[0.0; 3]; 65];
    big.geometry.spad_shape = [65, 1];
    big.data = vec![0.0; 3 * 65 * 50];
    let e = write_t3_to(&big, Vec::new(), &T3WriteOptions::default(), Path::new("w")).unwrap_err();
    assert!(matches!(e, Error::Argument { .. }), "{e}");
    let mut short = tiny(false);
    short.data.pop();
    let e = write_t3_to(
        &short,
        Vec::new(),
        &T3WriteOptions::default(),
        Path::new("w"),
    )
    .unwrap_err();
    assert_eq!(field(&e), "H");
}

/// Found by the `follow` fuzz target: a record count whose records would end past byte
/// 2^64 (4·count overflowed: a panic under overflow checks, a wrapped end otherwise) is a
/// one-line error on the count, for a pipe and for a growing file, never a panic.
#[test]
fn follower_refuses_a_record_count_past_2_64_bytes() {
    for n in [i64::MAX, 1 << 62, (1 << 62) + 7] {
        let mut h = H::new(0x0101_0304, 0);
        h.n = n;
        let bytes = file(&h, &[]);
        for file in [None, Some(Path::new("/nonexistent/t.ptu"))] {
            let e = super::Follower::reader(
                Box::new(Cursor::new(bytes.clone())),
                file,
                Path::new("t.ptu"),
                sidecar(1, 1, 4),
                Path::new("t.json"),
                super::FollowOptions::default(),
            )
            .unwrap_err();
            assert_eq!(field(&e), "TTResult_NumberOfRecords", "{e}");
            assert!(e.to_string().contains(&n.to_string()), "{e}");
        }
    }
    // A count just inside the limit is accepted (the stream then ends early: an error on
    // the records or markers, not the count).
    let mut h = H::new(0x0101_0304, 0);
    h.n = (1 << 61) - 100;
    let mut f = super::Follower::reader(
        Box::new(Cursor::new(file(&h, &[]))),
        None,
        Path::new("t.ptu"),
        sidecar(1, 1, 4),
        Path::new("t.json"),
        super::FollowOptions::default(),
    )
    .unwrap();
    assert_eq!(field(&f.next_row().unwrap_err()), "markers");
}
