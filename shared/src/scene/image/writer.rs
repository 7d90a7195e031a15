//! Writes an image section by section (host side, used by the DM and the test builders).
//!
//! Each record is allocated at its full [`Section::record_size`] and its fields are written
//! at the offsets of [`super::layout`], the same ones the view reads.

use super::layout::*;
use std::vec::Vec;

/// Accumulates the records of each section, then lays them out.
#[derive(Default)]
pub struct ImageWriter {
    sections: [Vec<u8>; SECTION_COUNT],
    counts: [u32; SECTION_COUNT],
}

/// One record being written: each field goes to its layout offset within the record.
pub struct Rec<'w>(&'w mut [u8]);

impl Rec<'_> {
    /// A stored scalar (f32) at offset `at`.
    pub fn f(self, at: usize, v: f32) -> Self {
        self.u(at, v.to_bits())
    }
    /// Consecutive stored scalars (a vector or matrix) from offset `at`.
    pub fn fs(mut self, at: usize, v: &[f32]) -> Self {
        for (k, x) in v.iter().enumerate() {
            self = self.f(at + 4 * k, *x);
        }
        self
    }
    /// A u32 (or a scalar already in its stored form) at offset `at`.
    pub fn u(self, at: usize, v: u32) -> Self {
        self.0[at..at + 4].copy_from_slice(&v.to_le_bytes());
        self
    }
    /// A u16 at offset `at` (indices, grid coordinates).
    pub fn h(self, at: usize, v: u16) -> Self {
        self.0[at..at + 2].copy_from_slice(&v.to_le_bytes());
        self
    }
    /// Consecutive u16s from offset `at`.
    pub fn hs(mut self, at: usize, v: &[u16]) -> Self {
        for (k, x) in v.iter().enumerate() {
            self = self.h(at + 2 * k, *x);
        }
        self
    }
    /// A byte at offset `at` (node info, screen rectangles).
    pub fn b(self, at: usize, v: u8) -> Self {
        self.0[at] = v;
        self
    }
}

impl ImageWriter {
    pub fn new() -> Self {
        Self::default()
    }
    /// Start a record in section `s` (not the texels: [`Self::push_texels`]), zeroed at its
    /// full size; returns its index and the record to fill.
    pub fn push(&mut self, s: Section) -> (u32, Rec<'_>) {
        let i = self.counts[s as usize];
        self.counts[s as usize] += 1;
        let v = &mut self.sections[s as usize];
        let start = v.len();
        v.resize(start + s.record_size(), 0);
        (i, Rec(&mut v[start..]))
    }
    /// Append texel bytes, returning their offset within the texel section.
    pub fn push_texels(&mut self, rgb: &[u8]) -> u32 {
        let v = &mut self.sections[Section::Texels as usize];
        let off = v.len() as u32;
        v.extend_from_slice(rgb);
        self.counts[Section::Texels as usize] = v.len() as u32;
        off
    }
    pub fn count(&self, s: Section) -> u32 {
        self.counts[s as usize]
    }
    /// Overwrite a u32 field of an already written record (patching `skip`).
    pub fn patch_u32(&mut self, s: Section, record: u32, field_offset: usize, v: u32) {
        let at = record as usize * s.record_size() + field_offset;
        self.sections[s as usize][at..at + 4].copy_from_slice(&v.to_le_bytes());
    }
    pub fn finish(self) -> Vec<u8> {
        let mut out = Vec::new();
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.resize(HEADER_SIZE, 0);
        for (i, data) in self.sections.iter().enumerate() {
            debug_assert_eq!(
                data.len(),
                self.counts[i] as usize * Section::ALL[i].record_size()
            );
            let off = if data.is_empty() { 0 } else { out.len() as u32 };
            let entry = TABLE_AT + TABLE_ENTRY_SIZE * i;
            out[entry..entry + 4].copy_from_slice(&off.to_le_bytes());
            out[entry + 4..entry + 8].copy_from_slice(&self.counts[i].to_le_bytes());
            out.extend_from_slice(data);
            while out.len() % 4 != 0 {
                out.push(0);
            }
        }
        let len = out.len() as u32;
        out[LENGTH_AT..LENGTH_AT + 4].copy_from_slice(&len.to_le_bytes());
        out
    }
}
