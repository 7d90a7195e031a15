//! The node boards a cluster is built of, as data: the memory a node's plan divides up and
//! the two scene banks it gives, read both by the firmware (`nc-fw`'s memory plan allocates
//! exactly these banks) and by the host, which checks a SceneImage against a named board
//! before it sends one (`links info --node`, `links render --nodes`, `links upload`).
//!
//! A node keeps two scene banks so that the next frame's scene can be broadcast into one
//! while the other renders (frame `f` uses bank `f % 2`); a scene that fits only the larger
//! bank can still be rendered as single frames.

use crate::cluster::spi::BANK;

pub use crate::cluster::profile::{BoardProfile, Core, LineProfile, LinkProfile};

/// A node computer board: its RAM and the scene banks of its memory plan (bytes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NodeBoard {
    /// The name the command line knows it by (`--node f407`).
    pub name: &'static str,
    /// DMA-reachable SRAM the plan gives the banks (memory.x's `SRAM` region, `.sram`).
    pub sram: usize,
    /// The RAM of `.data`, `.bss` and the stack (memory.x's `RAM` region): the CCM on the
    /// F407, which only the CPU reaches; on the F207 and the G0B1, which have no CCM, the low
    /// part of their SRAM.
    pub ccm: usize,
    /// The link's DMA banks in SRAM: two TX, two RX, one scratch.
    pub link_banks: usize,
    /// The scene banks: even frames', odd frames'.
    pub scene_banks: [usize; 2],
    /// Where the odd frames' bank lives (the even frames' is in SRAM).
    pub odd_bank_in: Memory,
}

/// A node board's RAM regions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Memory {
    /// DMA-reachable SRAM.
    Sram,
    /// RAM the CPU alone reaches (CCM).
    Ccm,
}

/// How a SceneImage fits a board's scene banks ([`NodeBoard::fit`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Fit {
    /// Both banks hold it: the next frame can be broadcast while this one renders.
    TwoBanks,
    /// Only the larger bank holds it: single frames only.
    OneBank,
    /// No bank holds it.
    TooBig,
}

impl Fit {
    /// The verdict in words, as `links info --node` prints it.
    pub const fn describe(self) -> &'static str {
        match self {
            Fit::TwoBanks => "fits two banks",
            Fit::OneBank => "fits one bank (single frames only)",
            Fit::TooBig => "does not fit",
        }
    }
}

/// The STM32F407VG's RAM: SRAM1 + SRAM2, and the CCM data RAM.
const F407_SRAM: usize = 128 * 1024;
const F407_CCM: usize = 64 * 1024;
const F407_LINK_BANKS: usize = 5 * BANK;

/// The STM32F207ZG's 128 KB of SRAM (SRAM1 112 KB + SRAM2 16 KB, contiguous, all
/// DMA-reachable, no CCM), split in two regions: the low 64 KB for `.data`, `.bss` and the
/// stack (the F407 firmware's statics take ~46 KB of its CCM, and the stack needs >= 16 KB),
/// the high 64 KB for the link's DMA banks and the scene banks.
const F207_RAM: usize = 64 * 1024;
const F207_SRAM: usize = 128 * 1024 - F207_RAM;
const F207_EVEN_BANK: usize = 40 * 1024;

/// The STM32G0B1RE's 144 KB of SRAM (one block at 0x2000_0000, all DMA-reachable, no CCM),
/// split as on the F207: the low 64 KB for `.data`, `.bss` and the stack (the firmwares'
/// statics take ~46 KB and the stack needs >= 16 KB, on the M0+ as on the M3), the high
/// 80 KB for the link's DMA banks and the scene banks.
const G0B1_RAM: usize = 64 * 1024;
const G0B1_SRAM: usize = 144 * 1024 - G0B1_RAM;
/// The G0B1's even frames' bank: the F207's (photo2 at 512x480 fits it).
const G0B1_EVEN_BANK: usize = F207_EVEN_BANK;

impl NodeBoard {
    /// The STM32F407VG node (STM32F4DISCOVERY), `nc-fw`'s board: two equal scene banks in
    /// SRAM, each half of what the link's DMA banks leave (in whole KB), so the next frame
    /// can be broadcast into one while the other renders; all of the CCM is left to `.data`,
    /// `.bss` and the stack (see docs/hardware.md).
    pub const F407: NodeBoard = NodeBoard {
        name: "f407",
        sram: F407_SRAM,
        ccm: F407_CCM,
        link_banks: F407_LINK_BANKS,
        scene_banks: [(F407_SRAM - F407_LINK_BANKS) / 2 / 1024 * 1024; 2],
        odd_bank_in: Memory::Sram,
    };

    /// The STM32F207ZG node (NUCLEO-F207ZG), `nc-fw --features board-f207`: in the SRAM
    /// region the statics leave, an even frames' bank of 40 KB (photo2, the paper's Table 5.2
    /// scene, is 38,948 bytes at 512x480: it renders as single frames) and an odd frames'
    /// bank of what the link's DMA banks leave beside it, in whole KB (16 KB: small scenes
    /// double-bank; photo1, 18,292 bytes, renders as single frames too). An equal split (2 x
    /// 28 KB) would double-bank photo1 but refuse photo2; see docs/hardware.md.
    pub const F207: NodeBoard = NodeBoard {
        name: "f207",
        sram: F207_SRAM,
        ccm: F207_RAM,
        link_banks: F407_LINK_BANKS,
        scene_banks: [
            F207_EVEN_BANK,
            (F207_SRAM - F407_LINK_BANKS - F207_EVEN_BANK) / 1024 * 1024,
        ],
        odd_bank_in: Memory::Sram,
    };

    /// The STM32G0B1RE node (NUCLEO-G0B1RE, Cortex-M0+), `nc-fw --features board-g0b1`: the
    /// F207's plan with 16 KB more SRAM, all given to the odd frames' bank. An even frames'
    /// bank of 40 KB (photo2, 38,948 bytes at 512x480, renders as single frames) and an odd
    /// frames' bank of what the link's DMA banks leave beside it, in whole KB (32 KB: photo1,
    /// 18,292 bytes, and every other bundled still double-bank). An equal split (2 x 36 KB)
    /// would refuse photo2; see docs/hardware.md.
    pub const G0B1: NodeBoard = NodeBoard {
        name: "g0b1",
        sram: G0B1_SRAM,
        ccm: G0B1_RAM,
        link_banks: F407_LINK_BANKS,
        scene_banks: [
            G0B1_EVEN_BANK,
            (G0B1_SRAM - F407_LINK_BANKS - G0B1_EVEN_BANK) / 1024 * 1024,
        ],
        odd_bank_in: Memory::Sram,
    };

    /// Every board the host knows, by name.
    pub const ALL: [NodeBoard; 3] = [Self::F407, Self::F207, Self::G0B1];

    /// The board called `name` (ASCII case ignored), if known.
    pub fn named(name: &str) -> Option<NodeBoard> {
        Self::ALL
            .into_iter()
            .find(|b| b.name.eq_ignore_ascii_case(name))
    }

    /// The bank frame `frame` renders from (`f % 2`).
    pub const fn bank(&self, frame: u32) -> usize {
        self.scene_banks[(frame % 2) as usize]
    }

    /// The larger bank: the most a single-frame scene may take.
    pub const fn largest_bank(&self) -> usize {
        let [a, b] = self.scene_banks;
        if a > b {
            a
        } else {
            b
        }
    }

    /// Bytes of the odd frames' bank placed in `memory` (its size, or 0 elsewhere): what
    /// the firmware allocates there.
    pub const fn odd_bank_bytes_in(&self, memory: Memory) -> usize {
        match (self.odd_bank_in, memory) {
            (Memory::Sram, Memory::Sram) | (Memory::Ccm, Memory::Ccm) => self.scene_banks[1],
            _ => 0,
        }
    }

    /// How a SceneImage of `bytes` bytes fits the scene banks.
    pub const fn fit(&self, bytes: usize) -> Fit {
        let [a, b] = self.scene_banks;
        let small = if a < b { a } else { b };
        if bytes <= small {
            Fit::TwoBanks
        } else if bytes <= self.largest_bank() {
            Fit::OneBank
        } else {
            Fit::TooBig
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_f407_plan_splits_the_sram_the_link_leaves_into_two_equal_banks() {
        let b = NodeBoard::F407;
        assert_eq!(b.link_banks, 5 * BANK);
        assert_eq!(b.scene_banks, [61_440, 61_440]);
        assert!(b.link_banks + 2 * b.scene_banks[0] <= b.sram);
        assert!(b.sram - b.link_banks - 2 * b.scene_banks[0] < 2048);
        assert_eq!(b.odd_bank_bytes_in(Memory::Sram), 61_440);
        assert_eq!(b.odd_bank_bytes_in(Memory::Ccm), 0);
        assert_eq!(b.fit(40_000), Fit::TwoBanks);
    }

    /// Worked by hand: 65,536 - 5 x 1,588 - 40,960 = 16,636 -> 16 KB for the odd bank.
    #[test]
    fn the_f207_plan_leaves_64_kb_for_statics_and_stack_and_banks_the_rest() {
        let b = NodeBoard::F207;
        assert_eq!(b.sram + b.ccm, 128 * 1024);
        assert_eq!(b.scene_banks, [40_960, 16_384]);
        assert!(b.link_banks + b.scene_banks[0] + b.scene_banks[1] <= b.sram);
        assert_eq!(
            b.sram - b.link_banks - b.scene_banks[0] - b.scene_banks[1],
            252
        );
        // photo1 and photo2 at 512x480 (docs/hardware.md).
        assert_eq!(
            (b.fit(16_384), b.fit(18_292)),
            (Fit::TwoBanks, Fit::OneBank)
        );
        assert_eq!((b.fit(38_948), b.fit(40_961)), (Fit::OneBank, Fit::TooBig));
        assert_eq!(NodeBoard::named("F207"), Some(b));
    }

    /// Worked by hand: 81,920 - 5 x 1,588 - 40,960 = 33,020 -> 32 KB for the odd bank.
    #[test]
    fn the_g0b1_plan_leaves_64_kb_for_statics_and_stack_and_banks_the_rest() {
        let b = NodeBoard::G0B1;
        assert_eq!(b.sram + b.ccm, 144 * 1024);
        assert_eq!(b.scene_banks, [40_960, 32_768]);
        assert!(b.link_banks + b.scene_banks[0] + b.scene_banks[1] <= b.sram);
        assert_eq!(
            b.sram - b.link_banks - b.scene_banks[0] - b.scene_banks[1],
            252
        );
        // photo1 and photo2 at 512x480 (docs/hardware.md).
        assert_eq!(
            (b.fit(18_292), b.fit(32_768), b.fit(32_769)),
            (Fit::TwoBanks, Fit::TwoBanks, Fit::OneBank)
        );
        assert_eq!((b.fit(38_948), b.fit(40_961)), (Fit::OneBank, Fit::TooBig));
        assert_eq!(NodeBoard::named("G0B1"), Some(b));
    }

    #[test]
    fn fit_names_the_banks_a_size_fits() {
        let b = NodeBoard {
            name: "t",
            sram: 0,
            ccm: 0,
            link_banks: 0,
            scene_banks: [100, 40],
            odd_bank_in: Memory::Sram,
        };
        assert_eq!(b.fit(0), Fit::TwoBanks);
        assert_eq!(b.fit(40), Fit::TwoBanks);
        assert_eq!(b.fit(41), Fit::OneBank);
        assert_eq!(b.fit(100), Fit::OneBank);
        assert_eq!(b.fit(101), Fit::TooBig);
        assert_eq!((b.bank(0), b.bank(1), b.bank(2)), (100, 40, 100));
        assert_eq!(b.largest_bank(), 100);
    }

    #[test]
    fn boards_are_found_by_name_in_any_case() {
        assert_eq!(NodeBoard::named("f407"), Some(NodeBoard::F407));
        assert_eq!(NodeBoard::named("F407"), Some(NodeBoard::F407));
        assert_eq!(NodeBoard::named("f429"), None);
    }
}
