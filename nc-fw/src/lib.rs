//! LINKS-1 node computer (NC) firmware for the STM32F407VG (feature `board-f407`, default),
//! the FPU-less STM32F207ZG (`board-f207`) or the Cortex-M0+ STM32G0B1RE (`board-g0b1`), with
//! the tracing kernels of its `kernel-f32` / `kernel-fixed` features ([`KERNELS`]).
//!
//! The behaviour is `links_core::node::run_node`; the link protocol is
//! `links_core::spi` (tested on the host against an emulated bus). This crate adds only the
//! board: the memory plan and pin map (plain data, checked by host tests) and, for the MCU,
//! the embassy-stm32 port of the SPI slave ([`port`]).
//!
//! Host tests: `tests/tests/fw_plan.rs` (the plan against real SceneImage sizes) and
//! `tests/tests/spi_link.rs` (the link protocol against an emulated bus).
#![cfg_attr(target_os = "none", no_std)]

#[cfg(target_os = "none")]
pub mod port;

/// The tracing kernels this build carries (its `kernel-*` features; `links_core::node`'s
/// renderer of that set is [`Renderer`]).
pub const KERNELS: links_core::node::Kernels = {
    use links_core::node::Kernels;
    match (cfg!(feature = "kernel-f32"), cfg!(feature = "kernel-fixed")) {
        (true, true) => Kernels::Both,
        (true, false) => Kernels::F32,
        (false, true) => Kernels::Fixed,
        (false, false) => panic!("nc-fw needs a kernel: feature kernel-f32 or kernel-fixed"),
    }
};

/// The node's renderer: both kernels (the image picks) or the one built.
#[cfg(all(feature = "kernel-f32", feature = "kernel-fixed"))]
pub type Renderer = links_core::node::TracingByImage;
/// The node's renderer: both kernels (the image picks) or the one built.
#[cfg(all(feature = "kernel-f32", not(feature = "kernel-fixed")))]
pub type Renderer = links_core::node::Tracing<f32>;
/// The node's renderer: both kernels (the image picks) or the one built.
#[cfg(not(feature = "kernel-f32"))]
pub type Renderer = links_core::node::Tracing<links_core::num::Fx>;

/// Where every large buffer lives (bytes): the board's data (the profile's node,
/// [`links_core::board::NodeBoard::F407`], [`links_core::board::NodeBoard::F207`] or
/// [`links_core::board::NodeBoard::G0B1`]), which
/// the host checks SceneImages against. See `docs/hardware.md`.
pub mod plan {
    use links_core::board::{BoardProfile, Memory, NodeBoard};
    use links_core::spi::BANK;

    /// The board profile this firmware is built for (`links_board`'s board feature).
    pub const PROFILE: BoardProfile = links_board::PROFILE;
    /// The board this firmware runs on: its RAM and the scene banks of this plan (the
    /// profile's node).
    pub const BOARD: NodeBoard = PROFILE.node;
    /// SRAM1 + SRAM2 (DMA-reachable) and CCM data RAM (CPU only): the board's.
    pub use links_board::{CCM, SRAM};
    /// The link's DMA banks: two TX, two RX, one scratch (in SRAM).
    pub const LINK_BANKS: usize = BOARD.link_banks;
    /// Scene bank of even frames (in SRAM; single frames, what the RC firmware renders, use
    /// this one).
    pub const SCENE_EVEN: usize = BOARD.scene_banks[0];
    /// Scene bank of odd frames (in SRAM or CCM, [`NodeBoard::odd_bank_in`]; the CPU reads
    /// scenes in place, DMA never touches them).
    pub const SCENE_ODD: usize = BOARD.scene_banks[1];
    /// The part of the odd frames' bank in SRAM: all of it or nothing.
    pub const SCENE_ODD_SRAM: usize = BOARD.odd_bank_bytes_in(Memory::Sram);
    /// The part of the odd frames' bank in CCM: all of it or nothing.
    pub const SCENE_ODD_CCM: usize = BOARD.odd_bank_bytes_in(Memory::Ccm);
    /// CCM left for .data, .bss (the executor's task futures, the link's shared state,
    /// RTT buffers) and the stack.
    pub const CCM_REST: usize = CCM - SCENE_ODD_CCM;

    const _: () = assert!(BOARD.sram == SRAM && BOARD.ccm == CCM);
    const _: () = assert!(LINK_BANKS == 5 * BANK);
    const _: () = assert!(BANK == PROFILE.dma_bank_bytes());
    const _: () = assert!(SCENE_ODD_SRAM + SCENE_ODD_CCM == SCENE_ODD);
    const _: () = assert!(LINK_BANKS + SCENE_EVEN + SCENE_ODD_SRAM <= SRAM);
    const _: () = assert!(SCENE_EVEN <= links_core::wire::MAX_SCENE);
    const _: () = assert!(SCENE_ODD <= links_core::wire::MAX_SCENE);
    const _: () = assert!(CCM_REST >= 32 * 1024);
}

/// Pins of the NC board (STM32F4DISCOVERY). See `docs/hardware.md`.
#[cfg(not(any(feature = "board-f207", feature = "board-g0b1")))]
pub mod pins {
    /// SPI1 (slave): SCK, MISO, MOSI, NSS (hardware chip-select input).
    pub const SPI1: [&str; 4] = ["PA5", "PA6", "PA7", "PA4"];
    /// The RC's chip-select line also goes here: an EXTI input that tells the link when a
    /// transfer starts and ends (the DMA is armed for a whole bank).
    pub const CS_SENSE: &str = "PB0";
    /// Handshake output to the RC ("armed, frame posted").
    pub const READY: &str = "PB1";
    /// The Discovery's accelerometer shares SPI1: its chip-select is held high.
    pub const ACCEL_CS: &str = "PE3";
    /// MISO's pin number on its port, GPIOA (driven by the slave-pin workaround in
    /// [`crate::port`]).
    pub const MISO_PIN: usize = 6;
    /// MOSI's pin number on GPIOA.
    pub const MOSI_PIN: usize = 7;
    /// The serial backup line (RS-485, `links_core::backup`): USART2 TX, RX, and the
    /// transceiver's driver enable (also its /RE).
    pub const BACKUP: [&str; 3] = ["PA2", "PA3", "PA1"];
    /// The node's backup-line address straps (pull-ups; a jumper to ground is a 1 bit):
    /// address = 1 + the 6-bit value, bit 0 first.
    pub const ADDRESS: [&str; 6] = ["PE7", "PE8", "PE9", "PE10", "PE11", "PE12"];
}

/// Pins of the NC board (NUCLEO-F207ZG, the Zio connectors CN7-CN10): SPI1 on the F407's
/// pins (AF5; PA7 is also the Ethernet PHY's RMII_CRS_DV, disconnected by removing JP6), the
/// chip-select sense on PE0 (PB0 drives LD1) and the backup line on USART2's other pins,
/// PD5/PD6 (PA2 and PA1 are the PHY's MDIO and REF_CLK). See `docs/hardware.md`.
#[cfg(feature = "board-f207")]
pub mod pins {
    /// SPI1 (slave): SCK, MISO, MOSI, NSS (hardware chip-select input).
    pub const SPI1: [&str; 4] = ["PA5", "PA6", "PA7", "PA4"];
    /// The RC's chip-select line also goes here (EXTI0).
    pub const CS_SENSE: &str = "PE0";
    /// Handshake output to the RC ("armed, frame posted").
    pub const READY: &str = "PB1";
    /// MISO's pin number on its port, GPIOA (driven by the slave-pin workaround in
    /// [`crate::port`]).
    pub const MISO_PIN: usize = 6;
    /// MOSI's pin number on GPIOA.
    pub const MOSI_PIN: usize = 7;
    /// The serial backup line (RS-485): USART2 TX, RX, and the transceiver's driver enable.
    pub const BACKUP: [&str; 3] = ["PD5", "PD6", "PD4"];
    /// The node's backup-line address straps (as on the F407 board).
    pub const ADDRESS: [&str; 6] = ["PE7", "PE8", "PE9", "PE10", "PE11", "PE12"];
}

/// Pins of the NC board on the NUCLEO-G0B1RE (UM2324: Arduino connectors CN5/CN6/CN8/CN9,
/// morpho CN7/CN10). SPI1 (AF0) on D3/D5/D4 = PB3/PB4/PB5, not on the Arduino SPI pins D13
/// (PA5 also drives the user LED LD4, a load on a bus line shared by eight nodes) to D11;
/// NSS on A2 = PA4, the F407's. The chip-select sense (D10 = PB0, EXTI0) and the handshake
/// (A3 = PB1) are the F407's pins. The backup line on USART1, D1/D0 = PC4/PC5 (USART2's
/// PA2/PA3 are the ST-LINK's virtual COM port), its driver enable on A1 = PA1 (the F407's);
/// the address straps on morpho pins of port C (no port E on the LQFP64). See
/// `docs/hardware.md`.
#[cfg(feature = "board-g0b1")]
pub mod pins {
    /// SPI1 (slave): SCK, MISO, MOSI, NSS (hardware chip-select input).
    pub const SPI1: [&str; 4] = ["PB3", "PB4", "PB5", "PA4"];
    /// The RC's chip-select line also goes here (EXTI0).
    pub const CS_SENSE: &str = "PB0";
    /// Handshake output to the RC ("armed, frame posted").
    pub const READY: &str = "PB1";
    /// MISO's pin number on its port, GPIOB (driven by the slave-pin workaround in
    /// [`crate::port`]).
    pub const MISO_PIN: usize = 4;
    /// MOSI's pin number on GPIOB.
    pub const MOSI_PIN: usize = 5;
    /// The serial backup line (RS-485): USART1 TX, RX, and the transceiver's driver enable.
    pub const BACKUP: [&str; 3] = ["PC4", "PC5", "PA1"];
    /// The node's backup-line address straps (pull-ups; a jumper to ground is a 1 bit),
    /// bit 0 first: morpho CN10-18, CN10-16, CN7-35, CN7-37, CN10-4, CN10-2.
    pub const ADDRESS: [&str; 6] = ["PC0", "PC1", "PC2", "PC3", "PC6", "PC8"];
}

/// The backup-line address the straps give: 1 + their value (1..=64).
pub const fn backup_address(straps: [bool; 6]) -> u8 {
    let mut v = 0u8;
    let mut i = 0;
    while i < 6 {
        if straps[i] {
            v |= 1 << i;
        }
        i += 1;
    }
    v + 1
}

/// The node served over the backup line (its SPI link dead): it renders the line's jobs in
/// the even scene bank (the SPI path's, idle then: `docs/hardware.md`) with the SPI path's
/// tracer.
pub mod backup_line {
    /// Pixels rendered per step: the line task waits for the node state no longer than one
    /// step's bookkeeping, never for a render; 32 pixels of photo1 (~6,300 instructions a
    /// pixel on the M4F) are ~1.2 ms of the 168 MHz core. At most
    /// `links_core::backup::OUTBOX_PIXELS`.
    pub const PIECE: usize = 32;
    /// With no job for this long the node takes its bank back and returns to SPI (ms).
    pub const IDLE_MS: u64 = 3000;
    const _: () = assert!(PIECE <= links_core::backup::OUTBOX_PIXELS);
}

#[cfg(test)]
mod tests {
    use links_core::board::BoardProfile;

    /// Every strap setting is a valid node address, all 64 distinct.
    #[test]
    fn the_address_straps_cover_the_backup_line() {
        let mut seen = [false; 65];
        for v in 0..64u8 {
            let a = super::backup_address(core::array::from_fn(|i| v & (1 << i) != 0));
            assert_eq!(a, v + 1);
            assert!((1..=links_core::backup::MAX_ADDR).contains(&a) && !seen[a as usize]);
            seen[a as usize] = true;
        }
    }

    /// The F207 build: the F207 profile's plan, the Q16.16 kernel (the core has no FPU),
    /// its pins distinct (`cargo test -p nc-fw --no-default-features --features board-f207`).
    #[cfg(feature = "board-f207")]
    #[test]
    fn the_firmware_constants_are_the_f207_profile() {
        let p = BoardProfile::F207;
        assert_eq!(super::plan::PROFILE, p);
        assert_eq!(super::plan::BOARD, p.node);
        assert_eq!(
            (super::plan::SRAM, super::plan::CCM),
            (64 * 1024, 64 * 1024)
        );
        assert_eq!(
            [super::plan::SCENE_EVEN, super::plan::SCENE_ODD],
            [40_960, 16_384]
        );
        assert_eq!(super::plan::LINK_BANKS, 5 * p.dma_bank_bytes());
        assert_eq!(links_board::CORE_CLOCK_HZ, 120_000_000);
        assert!(super::KERNELS.run(p.storage));
        if !cfg!(feature = "kernel-f32") {
            assert_eq!(super::KERNELS, p.kernels);
        }
        let mut all = super::pins::SPI1.to_vec();
        all.extend([super::pins::CS_SENSE, super::pins::READY]);
        all.extend(super::pins::BACKUP);
        all.extend(super::pins::ADDRESS);
        let n = all.len();
        all.sort();
        all.dedup();
        assert_eq!(all.len(), n, "no pin used twice");
    }

    /// The G0B1 build: the G0B1 profile's plan, the Q16.16 kernel (the M0+ has no FPU), its
    /// pins distinct (`cargo test -p nc-fw --no-default-features --features board-g0b1`).
    #[cfg(feature = "board-g0b1")]
    #[test]
    fn the_firmware_constants_are_the_g0b1_profile() {
        let p = BoardProfile::G0B1;
        assert_eq!(super::plan::PROFILE, p);
        assert_eq!(super::plan::BOARD, p.node);
        assert_eq!(
            (super::plan::SRAM, super::plan::CCM),
            (80 * 1024, 64 * 1024)
        );
        assert_eq!(
            [super::plan::SCENE_EVEN, super::plan::SCENE_ODD],
            [40_960, 32_768]
        );
        assert_eq!(super::plan::LINK_BANKS, 5 * p.dma_bank_bytes());
        assert_eq!(links_board::CORE_CLOCK_HZ, 64_000_000);
        assert_eq!(super::KERNELS, p.kernels);
        assert!(super::KERNELS.run(p.storage));
        let mut all = super::pins::SPI1.to_vec();
        all.extend([super::pins::CS_SENSE, super::pins::READY]);
        all.extend(super::pins::BACKUP);
        all.extend(super::pins::ADDRESS);
        let n = all.len();
        all.sort();
        all.dedup();
        assert_eq!(all.len(), n, "no pin used twice");
        // The slave-pin workaround's pin numbers are SPI1's MISO and MOSI.
        assert_eq!(
            [super::pins::MISO_PIN, super::pins::MOSI_PIN].map(|n| format!("PB{n}")),
            [super::pins::SPI1[1], super::pins::SPI1[2]]
        );
    }

    /// The node's memory plan and link banks are the F407 board profile's.
    #[cfg(not(any(feature = "board-f207", feature = "board-g0b1")))]
    #[test]
    fn the_firmware_constants_are_the_f407_profile() {
        let p = BoardProfile::F407;
        assert_eq!(super::plan::PROFILE, p);
        assert_eq!(super::KERNELS, p.kernels);
        assert_eq!(super::plan::BOARD, p.node);
        assert_eq!(super::plan::LINK_BANKS, 5 * p.dma_bank_bytes());
        assert_eq!(
            [super::plan::SCENE_EVEN, super::plan::SCENE_ODD],
            p.node.scene_banks
        );
        assert_eq!(
            links_core::spi::BANK,
            (8 + links_core::wire::MAX_MESSAGE + 1).div_ceil(4) * 4
        );
    }
}
