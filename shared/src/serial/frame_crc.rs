//! [`FrameCrc`]: the CRC-32 of a frame assembled from pixel runs added in any order
//! (the CRC register is linear over GF(2)).

use super::protocol::SerialError;

/// CRC-32 register without initial value or final xor: linear over GF(2), so the CRC of a
/// frame can be assembled from its runs in any order.
pub(super) const CRC32_RAW: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::Algorithm {
    width: 32,
    poly: 0x04c1_1db7,
    init: 0,
    refin: true,
    refout: true,
    xorout: 0,
    check: 0x2dfd_2d88,
    residue: 0,
});

/// The reflected CRC-32 polynomial.
const POLY_REFLECTED: u32 = 0xedb8_8320;

/// a · b mod P in the reflected representation (bit 31 = x^0).
fn gf2_mul(a: u32, mut b: u32) -> u32 {
    let mut product = 0;
    let mut bit = 1u32 << 31;
    while bit != 0 {
        if a & bit != 0 {
            product ^= b;
        }
        b = if b & 1 != 0 {
            (b >> 1) ^ POLY_REFLECTED
        } else {
            b >> 1
        };
        bit >>= 1;
    }
    product
}

/// The CRC register `reg` after `n` more zero bytes: reg · x^(8n) mod P.
fn shift_zeros(reg: u32, mut n: u64) -> u32 {
    // x^8 in the reflected representation.
    let mut power = 1u32 << (31 - 8);
    let mut result = reg;
    while n != 0 {
        if n & 1 != 0 {
            result = gf2_mul(result, power);
        }
        power = gf2_mul(power, power);
        n >>= 1;
    }
    result
}

/// The CRC-32 ([`CRC32`]) of a byte string of known length built from pieces added in any
/// order: the RC folds in pixel runs as nodes return them and still announces the CRC of
/// the whole frame in raster order. Each byte must be added exactly once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameCrc {
    len: u64,
    acc: u32,
}

impl FrameCrc {
    /// For a string of `len` bytes.
    pub const fn new(len: u64) -> Self {
        FrameCrc { len, acc: 0 }
    }

    /// Add the bytes `data` found at `offset`. Pieces past the end are refused.
    pub fn add(&mut self, offset: u64, data: &[u8]) -> Result<(), SerialError> {
        let end = offset
            .checked_add(data.len() as u64)
            .filter(|&e| e <= self.len)
            .ok_or(SerialError::OutOfRange)?;
        self.acc ^= shift_zeros(CRC32_RAW.checksum(data), self.len - end);
        Ok(())
    }

    /// The CRC-32 of the whole string (as `CRC32.checksum(whole)` once every byte is in).
    pub fn value(&self) -> u32 {
        // The initial all-ones register travels through every byte; the final xor.
        self.acc ^ shift_zeros(0xffff_ffff, self.len) ^ 0xffff_ffff
    }
}
