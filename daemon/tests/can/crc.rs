//! CRC-8 SAE J1850 against published check values, and against an independent
//! bit-by-bit implementation.

use wlnavd::can::crc::{crc8_j1850, CHECK};

/// Textbook shift register, one bit at a time, written independently of the
/// table-driven implementation under test.
fn crc8_bitwise(data: &[u8]) -> u8 {
    let mut reg: u8 = 0xFF;
    for &byte in data {
        for i in (0..8).rev() {
            let in_bit = (byte >> i) & 1;
            let top = reg >> 7;
            reg <<= 1;
            if top ^ in_bit == 1 {
                reg ^= 0x1D;
            }
        }
    }
    reg ^ 0xFF
}

/// AUTOSAR SWS CRC Library, `Crc_CalculateCRC8` (SAE J1850) example table, and the
/// catalogue check value.
const PUBLISHED: &[(&[u8], u8)] = &[
    (&[0x00, 0x00, 0x00, 0x00], 0x59),
    (&[0xF2, 0x01, 0x83], 0x37),
    (&[0x0F, 0xAA, 0x00, 0x55], 0x79),
    (&[0x00, 0xFF, 0x55, 0x11], 0xB8),
    (
        &[0x33, 0x22, 0x55, 0xAA, 0xBB, 0xCC, 0xDD, 0xEE, 0xFF],
        0xCB,
    ),
    (&[0x92, 0x6B, 0x55], 0x8C),
    (&[0xFF, 0xFF, 0xFF, 0xFF], 0x74),
    (b"123456789", 0x4B),
];

#[test]
fn published_vectors() {
    for &(data, want) in PUBLISHED {
        assert_eq!(crc8_j1850(data), want, "table-driven, input {data:02X?}");
        assert_eq!(
            crc8_bitwise(data),
            want,
            "bitwise reference, input {data:02X?}"
        );
    }
    assert_eq!(CHECK, 0x4B);
}

#[test]
fn table_matches_bitwise_on_many_inputs() {
    // Every single byte, and a deterministic spread of 7-byte payloads (the
    // protected part of a frame).
    for b in 0..=255u8 {
        assert_eq!(crc8_j1850(&[b]), crc8_bitwise(&[b]), "byte {b:#04x}");
    }
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    for _ in 0..20_000 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let bytes = x.to_le_bytes();
        assert_eq!(crc8_j1850(&bytes[..7]), crc8_bitwise(&bytes[..7]));
    }
}

#[test]
fn detects_every_single_and_double_bit_error_in_a_frame() {
    let payload = [0x10, 0x27, 0x78, 0xEC, 0x39, 0x30, 0x21];
    let good = crc8_j1850(&payload);
    for i in 0..56 {
        for j in i..56 {
            let mut p = payload;
            p[i / 8] ^= 1 << (i % 8);
            if j != i {
                p[j / 8] ^= 1 << (j % 8);
            }
            assert_ne!(crc8_j1850(&p), good, "bits {i},{j}");
        }
    }
}
