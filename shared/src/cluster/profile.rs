//! The board a cluster is built of, as one value: the SPI link between the RC and its nodes
//! ([`LinkProfile`]: bit rate, chip-select set-up and hold, the frame's header and trailer,
//! nodes per bus, whether the RC overlaps the wire with its own work), the node's memory
//! ([`NodeBoard`]: DMA banks, scene banks), the core and its clock ([`Core`]).
//!
//! [`BoardProfile::F207`] is the FPU-less board (NUCLEO-F207ZG, Cortex-M3 at 120 MHz) whose
//! nodes run the Q16.16 kernel: the host sends its nodes Q16.16 images ([`BoardProfile::storage`]).
//! [`BoardProfile::G0B1`] is the smallest (NUCLEO-G0B1RE, Cortex-M0+ at 64 MHz, 144 KB of
//! SRAM), Q16.16 only.
//!
//! [`BoardProfile::F407`] is what the firmware builds by default: `links_core::spi` takes its header
//! and trailer sizes (and with them the DMA bank size) from it, `rc-fw` its SPI clock,
//! chip-select timing and nodes per bus, `nc-fw` its memory plan. [`BoardProfile::IDEAL`] is
//! the idealised link the simulator used before it knew the board (42 MHz, a 4-byte header,
//! 0.5 µs per transfer, any number of nodes on one bus, an RC that overlaps). The simulator
//! takes either (`links render --nodes N --board f407|ideal`); the cost-model weights of a
//! core live in the host's cost model, keyed by [`Core`].

use crate::cluster::board::NodeBoard;
use crate::cluster::root::MAX_NODES;
use crate::cluster::spi;
use crate::cluster::wire::MAX_MESSAGE;
use crate::node::Kernels;
use crate::num::Storage;

/// The CPU core of a board: it selects the cost-model weights the simulator charges the
/// node's and the RC's work with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Core {
    /// Cortex-M4 with the single-precision FPU (STM32F407), rendering in hard-float `f32`.
    CortexM4F,
    /// Cortex-M3 without an FPU (STM32F207), rendering in Q16.16 (or soft-float `f32`).
    CortexM3,
    /// Cortex-M0+ (STM32G0B1: ARMv6-M, no FPU, no 32x32->64 multiply, no divide
    /// instruction), rendering in Q16.16.
    CortexM0Plus,
}

impl Core {
    /// The core's name as printed in summaries.
    pub const fn name(self) -> &'static str {
        match self {
            Core::CortexM4F => "Cortex-M4F",
            Core::CortexM3 => "Cortex-M3",
            Core::CortexM0Plus => "Cortex-M0+",
        }
    }
}

/// The SPI link between the RC and the nodes of one bus.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkProfile {
    /// SPI clock of one bus (bits per second).
    pub bit_rate_hz: u32,
    /// Chip-select asserted to the first clock edge (ns), each transfer.
    pub cs_setup_ns: u32,
    /// Chip-select held high after a transfer before the next selection (ns).
    pub cs_hold_ns: u32,
    /// Bytes of the header phase every transfer starts with.
    pub header_bytes: u16,
    /// Bytes of the trailer phase that ends an exchange (broadcasts have none).
    pub trailer_bytes: u16,
    /// Nodes one bus drives (one chip-select and one handshake line each).
    pub nodes_per_bus: u16,
    /// Whether the RC clocks the wire while it composes the next transfer and decodes the
    /// last one (DMA double buffering on the RC); `false`: one at a time.
    pub rc_overlaps: bool,
    /// SPI buses the root of a relay tree drives its relays on (`rc-fw --features
    /// relay-root`; `links_core::relay::TwoLinks` for two): the simulator's default root
    /// buses under a relay tree.
    pub root_links: u16,
}

impl LinkProfile {
    /// The firmware's link (`rc-fw`, `nc-fw`, `links_core::spi`): SPI1 at 21 MHz (APB2 84 MHz
    /// / 4: what holds for a full-duplex slave behind the MISO multiplexer), 8 + 15 µs of
    /// chip-select set-up and hold (the node's EXTI wakes its link task, which drives MISO;
    /// after the transfer it stops and re-arms its DMA), the 8-byte header (magic, kind,
    /// length, body CRC-16, header CRC-16) and the 1-byte ACK/NAK trailer, 8 nodes per bus
    /// (`rc-fw`'s pin table), and an RC whose bus task clocks the wire on an interrupt
    /// executor while the root logic composes the next transfer ([`spi::RC_OVERLAPS`]). A
    /// root of relays drives them on SPI1 and SPI2 (SPI2 on APB1, 42 MHz / 2: the same
    /// 21 MHz), half the relays on each (`docs/hardware.md`).
    pub const F407: LinkProfile = LinkProfile {
        bit_rate_hz: 21_000_000,
        cs_setup_ns: 8_000,
        cs_hold_ns: 15_000,
        header_bytes: 8,
        trailer_bytes: 1,
        nodes_per_bus: 8,
        rc_overlaps: spi::RC_OVERLAPS,
        root_links: 2,
    };

    /// The F207 boards' link: the F407's protocol (header, trailer, 8 nodes per bus, an RC
    /// whose bus task clocks the wire while the root logic composes the next transfer,
    /// [`spi::RC_OVERLAPS`], as on the F407) at the F207's speeds. SPI1 at 15 MHz
    /// (APB2 60 MHz / 4, the same divider that holds on the F407 for a full-duplex slave
    /// behind the MISO multiplexer; the F207's SPI slave limit is 30 MHz); chip-select
    /// set-up and hold are the F407's 8 + 15 µs of software (EXTI wake-up, DMA re-arm) scaled
    /// by the clocks, 168 / 120 = 1.4: 11.2 + 21 µs, the set-up rounded up to the RC timer's
    /// whole µs: 12 + 21 µs (an estimate until measured on a board).
    pub const F207: LinkProfile = LinkProfile {
        bit_rate_hz: 15_000_000,
        cs_setup_ns: 12_000,
        cs_hold_ns: 21_000,
        root_links: 1,
        ..Self::F407
    };

    /// The G0B1 boards' link: the F407's protocol at the G0's speeds. SPI1 at 16 MHz (APB
    /// 64 MHz / 4, the divider that holds on the F407 and the F207 for a full-duplex slave
    /// behind the MISO multiplexer; half the G0's 32 MHz SPI maximum); chip-select set-up and
    /// hold are the F407's 8 + 15 µs of software scaled by the clocks, 168 / 64 = 2.625:
    /// 21 + 39.4 µs, rounded up to the RC timer's whole µs: 21 + 40 µs (an estimate until
    /// measured on a board; the M0+'s Thumb-1 code takes more instructions than the M4's for
    /// the same work, so if anything it is low).
    pub const G0B1: LinkProfile = LinkProfile {
        bit_rate_hz: 16_000_000,
        cs_setup_ns: 21_000,
        cs_hold_ns: 40_000,
        root_links: 1,
        ..Self::F407
    };

    /// The simulator's idealised link before the board profile: 42 MHz (SPI1's maximum),
    /// a 4-byte length header, no trailer, 0.5 µs of handshake per transfer (counted as
    /// chip-select set-up: about 80 cycles at 168 MHz, an estimate), every node on one bus,
    /// an RC that overlaps the wire with its work.
    pub const IDEAL: LinkProfile = LinkProfile {
        bit_rate_hz: 42_000_000,
        cs_setup_ns: 500,
        cs_hold_ns: 0,
        header_bytes: 4,
        trailer_bytes: 0,
        nodes_per_bus: MAX_NODES as u16,
        rc_overlaps: true,
        root_links: 1,
    };

    /// Size of one DMA bank: header, the largest frame, trailer, rounded up to a word.
    pub const fn dma_bank_bytes(&self) -> usize {
        (self.header_bytes as usize + MAX_MESSAGE + self.trailer_bytes as usize).div_ceil(4) * 4
    }

    /// Chip-select set-up and hold of one transfer (ns).
    pub const fn handshake_ns(&self) -> u32 {
        self.cs_setup_ns + self.cs_hold_ns
    }
}

/// The serial backup line ([`crate::backup`]): one RS-485 multi-drop UART pair from the RC
/// to every node (USART2 on the F407 boards, docs/hardware.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LineProfile {
    /// UART bit rate (bits per second).
    pub bit_rate_hz: u32,
    /// Bits on the line per byte (8N1: start, 8 data, stop).
    pub bits_per_byte: u32,
    /// Line turnaround before each frame (ns): the sender's transceiver enable, the receiver
    /// noticing the frame ended (UART idle line) and answering.
    pub turnaround_ns: u32,
    /// How long the RC waits for an addressed node's answer before it counts it absent (µs).
    pub reply_timeout_us: u32,
}

impl LineProfile {
    /// USART2 at 1 Mbit/s, 8N1, on MAX3485 transceivers (10 Mbit/s parts, enable time
    /// < 1 µs); 20 µs of turnaround (the node's idle-line interrupt, decode and DE switch),
    /// 1 ms reply timeout.
    pub const F407: LineProfile = LineProfile {
        bit_rate_hz: 1_000_000,
        bits_per_byte: 10,
        turnaround_ns: 20_000,
        reply_timeout_us: 1_000,
    };

    /// The F207 boards' line: USART2 at 1 Mbit/s (APB1 30 MHz, oversampling by 16), the
    /// F407's 20 µs of software turnaround scaled by the clocks (x 1.4).
    pub const F207: LineProfile = LineProfile {
        turnaround_ns: 28_000,
        ..Self::F407
    };

    /// The G0B1 boards' line: USART1 at 1 Mbit/s (its kernel clock, PCLK 64 MHz, oversampled
    /// by 16: a divider of exactly 64), the F407's 20 µs of software turnaround scaled by the
    /// clocks (x 2.625).
    pub const G0B1: LineProfile = LineProfile {
        turnaround_ns: 52_500,
        ..Self::F407
    };

    /// Time on the line of a frame of `bytes` bytes, turnaround included (ns).
    pub const fn frame_ns(&self, bytes: usize) -> u64 {
        self.turnaround_ns as u64
            + (bytes as u64 * self.bits_per_byte as u64 * 1_000_000_000)
                .div_ceil(self.bit_rate_hz as u64)
    }
}

/// One board: its link, its node's memory, its core and clock.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BoardProfile {
    /// The name the command line knows it by (`--board f407`).
    pub name: &'static str,
    pub link: LinkProfile,
    /// The serial backup line.
    pub backup: LineProfile,
    /// The node's RAM, its link DMA banks and its two scene banks.
    pub node: NodeBoard,
    /// The core of the nodes and the RC (the cost model's weights).
    pub core: Core,
    /// Core clock of the nodes and the RC (Hz).
    pub core_clock_hz: u32,
    /// The kernels the node firmware carries by default (`nc-fw`'s `kernel-*` features).
    pub kernels: Kernels,
    /// The storage the host compiles the nodes' SceneImages in unless told otherwise (the
    /// kernel the core runs best: f32 with an FPU, Q16.16 without).
    pub storage: Storage,
    /// How long the RC lets a node holding work stay silent before it declares it dead
    /// (µs; [`RootConfig::timeout_us`](crate::cluster::root::RootConfig::timeout_us)). A
    /// node speaks once per pixel run, so this must exceed the longest run its core renders.
    pub node_timeout_us: u64,
}

/// The STM32F407's core clock: 8 MHz crystal, PLL to 168 MHz (`links-board`'s clock tree).
const F407_CORE_CLOCK_HZ: u32 = 168_000_000;
/// The STM32F207's core clock: the ST-LINK's 8 MHz MCO (HSE bypass), PLL to 120 MHz.
const F207_CORE_CLOCK_HZ: u32 = 120_000_000;
/// The STM32G0B1's core clock: the 16 MHz HSI16, PLL to 64 MHz (the G0's maximum).
const G0B1_CORE_CLOCK_HZ: u32 = 64_000_000;

/// The F407 node's silence bound: 0.5 s, 2.5 times its longest run on photo1 at 512x480
/// (0.15-0.2 s); a false alarm raises the time-out to twice the silence it missed
/// (docs/reliability.md).
const F407_NODE_TIMEOUT_US: u64 = 500_000;
/// The slower cores' bounds keep the F407's margin: its 0.5 s times how much longer their
/// node takes over the same frame (photo1 512x480 on one node, `links render
/// scenes/photo1.ron --nodes 1 --board B`: F407 23.0 s, F207 172 s = 7.5 times, G0B1 675 s
/// = 29 times; a host test holds the ratios to their cost models within a factor of two).
const F207_NODE_TIMEOUT_US: u64 = 4_000_000;
const G0B1_NODE_TIMEOUT_US: u64 = 15_000_000;

impl BoardProfile {
    /// What the firmware builds today: STM32F4DISCOVERY boards (STM32F407VG at 168 MHz)
    /// on the [`LinkProfile::F407`] link, the node's memory plan [`NodeBoard::F407`].
    pub const F407: BoardProfile = BoardProfile {
        name: "f407",
        link: LinkProfile::F407,
        backup: LineProfile::F407,
        node: NodeBoard::F407,
        core: Core::CortexM4F,
        core_clock_hz: F407_CORE_CLOCK_HZ,
        kernels: Kernels::Both,
        storage: Storage::F32,
        node_timeout_us: F407_NODE_TIMEOUT_US,
    };

    /// NUCLEO-F207ZG boards (STM32F207ZG, Cortex-M3 at 120 MHz, no FPU) on the
    /// [`LinkProfile::F207`] link, the node's memory plan [`NodeBoard::F207`]; the nodes carry
    /// the Q16.16 kernel only by default (`nc-fw --features kernel-f32` adds soft-float f32).
    pub const F207: BoardProfile = BoardProfile {
        name: "f207",
        link: LinkProfile::F207,
        backup: LineProfile::F207,
        node: NodeBoard::F207,
        core: Core::CortexM3,
        core_clock_hz: F207_CORE_CLOCK_HZ,
        kernels: Kernels::Fixed,
        storage: Storage::Q16_16,
        node_timeout_us: F207_NODE_TIMEOUT_US,
    };

    /// NUCLEO-G0B1RE boards (STM32G0B1RE, Cortex-M0+ at 64 MHz, no FPU, 144 KB of SRAM) on
    /// the [`LinkProfile::G0B1`] link, the node's memory plan [`NodeBoard::G0B1`]; the nodes
    /// carry the Q16.16 kernel only (the kernel the M0+ runs best: soft-float `f32` takes 2.4
    /// times its instructions there, docs/cortex-m-bench.md).
    pub const G0B1: BoardProfile = BoardProfile {
        name: "g0b1",
        link: LinkProfile::G0B1,
        backup: LineProfile::G0B1,
        node: NodeBoard::G0B1,
        core: Core::CortexM0Plus,
        core_clock_hz: G0B1_CORE_CLOCK_HZ,
        kernels: Kernels::Fixed,
        storage: Storage::Q16_16,
        node_timeout_us: G0B1_NODE_TIMEOUT_US,
    };

    /// The simulator's idealised link ([`LinkProfile::IDEAL`]) on the F407's nodes (same
    /// core, clock and scene banks).
    pub const IDEAL: BoardProfile = BoardProfile {
        name: "ideal",
        link: LinkProfile::IDEAL,
        backup: LineProfile::F407,
        node: NodeBoard::F407,
        core: Core::CortexM4F,
        core_clock_hz: F407_CORE_CLOCK_HZ,
        kernels: Kernels::Both,
        storage: Storage::F32,
        node_timeout_us: F407_NODE_TIMEOUT_US,
    };

    /// Every profile the host knows, by name.
    pub const ALL: [BoardProfile; 4] = [Self::F407, Self::F207, Self::G0B1, Self::IDEAL];

    /// The profile called `name` (ASCII case ignored), if known.
    pub fn named(name: &str) -> Option<BoardProfile> {
        Self::ALL
            .into_iter()
            .find(|b| b.name.eq_ignore_ascii_case(name))
    }

    /// Size of one link DMA bank on this board.
    pub const fn dma_bank_bytes(&self) -> usize {
        self.link.dma_bank_bytes()
    }

    /// Buses a star of `nodes` nodes needs at [`LinkProfile::nodes_per_bus`] (at least 1).
    pub const fn buses_for(&self, nodes: u16) -> u16 {
        let per = if self.link.nodes_per_bus == 0 {
            1
        } else {
            self.link.nodes_per_bus
        };
        let b = nodes.div_ceil(per);
        if b == 0 {
            1
        } else {
            b
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The link code's constants are the F407 profile's.
    #[test]
    fn the_spi_link_code_is_built_from_the_f407_profile() {
        let l = BoardProfile::F407.link;
        assert_eq!(spi::HEADER, l.header_bytes as usize);
        assert_eq!(spi::TRAILER, l.trailer_bytes as usize);
        assert_eq!(spi::BANK, BoardProfile::F407.dma_bank_bytes());
        assert_eq!(spi::RC_OVERLAPS, l.rc_overlaps);
        assert_eq!(BoardProfile::F407.node.link_banks, 5 * spi::BANK);
        // Worked by hand: 8 + 1,576 + 1 = 1,585 bytes, rounded up to 1,588.
        assert_eq!(BoardProfile::F407.dma_bank_bytes(), 1588);
        assert_eq!(BoardProfile::IDEAL.dma_bank_bytes(), 1580);
    }

    #[test]
    fn the_profiles_hold_the_documented_numbers() {
        let (f, i) = (BoardProfile::F407, BoardProfile::IDEAL);
        assert_eq!(
            (
                f.link.bit_rate_hz,
                f.link.handshake_ns(),
                f.link.nodes_per_bus
            ),
            (21_000_000, 23_000, 8)
        );
        assert!(f.link.rc_overlaps && i.link.rc_overlaps);
        assert_eq!(
            (
                i.link.bit_rate_hz,
                i.link.handshake_ns(),
                i.link.header_bytes
            ),
            (42_000_000, 500, 4)
        );
        assert_eq!(i.link.trailer_bytes, 0);
        assert_eq!(f.core_clock_hz, 168_000_000);
        assert_eq!((f.node, f.core), (i.node, i.core));
    }

    /// The F207: the F407's protocol (so the same DMA bank) at its own speeds, a
    /// Cortex-M3 at 120 MHz sent Q16.16 images.
    #[test]
    fn the_f207_profile_holds_the_documented_numbers() {
        let (f, g) = (BoardProfile::F407, BoardProfile::F207);
        assert_eq!(g.dma_bank_bytes(), f.dma_bank_bytes());
        assert_eq!(
            (
                g.link.bit_rate_hz,
                g.link.handshake_ns(),
                g.link.nodes_per_bus
            ),
            (15_000_000, 33_000, 8)
        );
        assert_eq!(g.link.rc_overlaps, f.link.rc_overlaps);
        assert_eq!((g.core, g.core_clock_hz), (Core::CortexM3, 120_000_000));
        assert_eq!((g.kernels, g.storage), (Kernels::Fixed, Storage::Q16_16));
        assert_eq!((f.kernels, f.storage), (Kernels::Both, Storage::F32));
        // 262 bytes at 1 Mbit/s: 2,620 µs + 28 µs.
        assert_eq!(g.backup.frame_ns(crate::backup::MAX_FRAME), 2_648_000);
        assert_eq!(g.node, NodeBoard::F207);
    }

    /// The G0B1: the F407's protocol (so the same DMA bank) at its own speeds, a Cortex-M0+
    /// at 64 MHz sent Q16.16 images.
    #[test]
    fn the_g0b1_profile_holds_the_documented_numbers() {
        let (f, g) = (BoardProfile::F407, BoardProfile::G0B1);
        assert_eq!(g.dma_bank_bytes(), f.dma_bank_bytes());
        assert_eq!(
            (
                g.link.bit_rate_hz,
                g.link.handshake_ns(),
                g.link.nodes_per_bus
            ),
            (16_000_000, 61_000, 8)
        );
        assert_eq!(g.link.rc_overlaps, f.link.rc_overlaps);
        assert_eq!((g.core, g.core_clock_hz), (Core::CortexM0Plus, 64_000_000));
        assert_eq!((g.kernels, g.storage), (Kernels::Fixed, Storage::Q16_16));
        // 262 bytes at 1 Mbit/s: 2,620 µs + 52.5 µs.
        assert_eq!(g.backup.frame_ns(crate::backup::MAX_FRAME), 2_672_500);
        assert_eq!(g.node, NodeBoard::G0B1);
        assert_eq!(BoardProfile::named("G0B1"), Some(g));
        assert_eq!(g.core.name(), "Cortex-M0+");
    }

    /// The backup line's timing, worked by hand: a 262-byte frame is 2,620 bits at 1 Mbit/s
    /// = 2,620 µs, plus 20 µs of turnaround.
    #[test]
    fn the_backup_line_charges_bits_and_turnaround() {
        let l = BoardProfile::F407.backup;
        assert_eq!(l.frame_ns(crate::backup::MAX_FRAME), 2_640_000);
        assert_eq!(l.frame_ns(0), 20_000);
        assert_eq!(BoardProfile::IDEAL.backup, l);
    }

    #[test]
    fn profiles_are_found_by_name_and_count_their_buses() {
        assert_eq!(BoardProfile::named("F407"), Some(BoardProfile::F407));
        assert_eq!(BoardProfile::named("ideal"), Some(BoardProfile::IDEAL));
        assert_eq!(BoardProfile::named("F207"), Some(BoardProfile::F207));
        assert_eq!(BoardProfile::named("f429"), None);
        let f = BoardProfile::F407;
        assert_eq!(
            [0, 1, 8, 9, 64, 256].map(|n| f.buses_for(n)),
            [1, 1, 1, 2, 8, 32]
        );
        assert_eq!(BoardProfile::IDEAL.buses_for(256), 1);
        // A root link holds no more relays than a relay root's `RelayedBus` keeps state for.
        for b in [BoardProfile::F407, BoardProfile::F207, BoardProfile::G0B1] {
            assert!(b.link.nodes_per_bus as usize <= crate::cluster::relay::MAX_RELAYS);
        }
        // The F407's root of relays drives them on SPI1 and SPI2; the others on one bus.
        assert_eq!(BoardProfile::ALL.map(|b| b.link.root_links), [2, 1, 1, 1]);
    }
}
