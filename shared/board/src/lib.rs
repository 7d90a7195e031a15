//! The board both LINKS-1 firmwares run on, chosen by cargo feature: `board-f407`
//! (default; STM32F407VG on an STM32F4DISCOVERY), `board-f207` (STM32F207ZG on a
//! NUCLEO-F207ZG, no FPU) or `board-g0b1` (STM32G0B1RE on a NUCLEO-G0B1RE, Cortex-M0+). It
//! gives the board profile ([`PROFILE`]), the RAM sizes their
//! memory plans divide up, and for the MCU the one bring-up they share: the clock tree
//! ([`config`], [`init`]) and the zeroed DMA-reachable `.sram` region ([`take_sram!`]), and
//! the serial backup line's RS-485 port (`rs485`). Pins and memory plans stay with each
//! firmware (`nc-fw`, `rc-fw`). Features, not targets, pick the board: a target names a core,
//! not a chip (the M4F firmware runs on the F407 and F429 alike), and the chip feature of
//! `embassy-stm32` must be named exactly once.
#![no_std]

#[cfg(any(
    all(feature = "board-f407", feature = "board-f207"),
    all(feature = "board-f407", feature = "board-g0b1"),
    all(feature = "board-f207", feature = "board-g0b1")
))]
compile_error!(
    "choose one board: board-f407 (default), board-f207 or board-g0b1 (--no-default-features)"
);
#[cfg(not(any(feature = "board-f407", feature = "board-f207", feature = "board-g0b1")))]
compile_error!("choose a board: feature board-f407, board-f207 or board-g0b1");

#[cfg(target_os = "none")]
pub mod rs485;

/// The board profile both firmwares are built for.
#[cfg(not(any(feature = "board-f207", feature = "board-g0b1")))]
pub const PROFILE: links_core::board::BoardProfile = links_core::board::BoardProfile::F407;
/// The board profile both firmwares are built for.
#[cfg(feature = "board-f207")]
pub const PROFILE: links_core::board::BoardProfile = links_core::board::BoardProfile::F207;
/// The board profile both firmwares are built for.
#[cfg(feature = "board-g0b1")]
pub const PROFILE: links_core::board::BoardProfile = links_core::board::BoardProfile::G0B1;

/// DMA-reachable SRAM of the banks (memory.x's `SRAM`): the profile node's.
pub const SRAM: usize = PROFILE.node.sram;
/// RAM of `.data`, `.bss` and the stack (memory.x's `RAM`: the F407's CCM, the F207's and
/// the G0B1's low SRAM): the profile node's.
pub const CCM: usize = PROFILE.node.ccm;

/// The core clock the clock tree below gives: the board profile's.
pub const CORE_CLOCK_HZ: u32 = PROFILE.core_clock_hz;
/// The HSE input: the Discovery's 8 MHz crystal, the Nucleo's 8 MHz MCO from its ST-LINK.
pub const HSE_HZ: u32 = 8_000_000;
/// The G0's internal 16 MHz RC oscillator (HSI16), the NUCLEO-G0B1RE's PLL input: it
/// needs no HSE source on the board (the ST-LINK's MCO or a crystal, each a solder-bridge
/// option in UM2324), and its 1 % suits the SPI link (clocked by the RC) and the 1 Mbit/s
/// backup line; USB runs from HSI48, trimmed to the host's start-of-frame packets by the
/// CRS.
pub const HSI16_HZ: u32 = 16_000_000;
// The PLL of [`config`]: HSE / 4 (prediv) x 168 (mul) / 2 (P) must give the profile's clock.
#[cfg(not(any(feature = "board-f207", feature = "board-g0b1")))]
const _: () = assert!(HSE_HZ / 4 * 168 / 2 == CORE_CLOCK_HZ);
// The PLL of [`config`]: HSI16 / 1 (M) x 8 (N: VCO 128 MHz) / 2 (R) must give the profile's
// clock.
#[cfg(feature = "board-g0b1")]
const _: () = assert!(HSI16_HZ * 8 / 2 == CORE_CLOCK_HZ);
// The PLL of [`config`]: HSE / 8 (prediv, 1 MHz in) x 240 (VCO 240 MHz) / 2 (P), / 5 (Q:
// 48 MHz for USB) must give the profile's clock.
#[cfg(feature = "board-f207")]
const _: () = assert!(HSE_HZ / 8 * 240 / 2 == CORE_CLOCK_HZ && HSE_HZ / 8 * 240 / 5 == 48_000_000);

/// The clock tree: 120 MHz core from the ST-LINK's 8 MHz MCO (HSE bypass), APB2 60 MHz
/// (SPI1 up to 30 MHz), APB1 30 MHz, 48 MHz for USB; flash wait states for 2.7-3.6 V.
#[cfg(all(target_os = "none", feature = "board-f207"))]
pub fn config() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    use embassy_stm32::time::Hertz;
    let mut c = embassy_stm32::Config::default();
    c.rcc.hse = Some(Hse {
        freq: Hertz(HSE_HZ),
        mode: HseMode::Bypass,
    });
    c.rcc.pll_src = PllSource::HSE;
    c.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV8,
        mul: PllMul::MUL240,
        divp: Some(PllPDiv::DIV2),
        divq: Some(PllQDiv::DIV5),
        divr: None,
    });
    c.rcc.ahb_pre = AHBPrescaler::DIV1;
    c.rcc.apb1_pre = APBPrescaler::DIV4;
    c.rcc.apb2_pre = APBPrescaler::DIV2;
    c.rcc.sys = Sysclk::PLL1_P;
    c.rcc.voltage = VoltageScale::Range0;
    c
}

/// The clock tree: HSI16 -> PLL (VCO 128 MHz) -> 64 MHz core (R), AHB and APB 64 MHz
/// (SPI1 up to 32 MHz, USART1 at 1 Mbit/s from PCLK); HSI48 with CRS sync from USB SOF
/// for USB (the RC); flash wait states for range 1 (2 at 64 MHz, embassy sets them).
#[cfg(all(target_os = "none", feature = "board-g0b1"))]
pub fn config() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut c = embassy_stm32::Config::default();
    c.rcc.hsi = Some(Hsi {
        sys_div: HsiSysDiv::DIV1,
    });
    c.rcc.pll = Some(Pll {
        source: PllSource::HSI,
        prediv: PllPreDiv::DIV1,
        mul: PllMul::MUL8,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    c.rcc.sys = Sysclk::PLL1_R;
    c.rcc.ahb_pre = AHBPrescaler::DIV1;
    c.rcc.apb1_pre = APBPrescaler::DIV1;
    c.rcc.voltage_range = VoltageRange::RANGE1;
    c.rcc.hsi48 = Some(Hsi48Config {
        sync_from_usb: true,
    });
    c.rcc.mux.usbsel = mux::Usbsel::HSI48;
    c
}

/// The clock tree: 8 MHz crystal -> 168 MHz core, APB2 84 MHz (SPI1 up to 42 MHz), 48 MHz
/// for USB.
#[cfg(all(
    target_os = "none",
    not(any(feature = "board-f207", feature = "board-g0b1"))
))]
pub fn config() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    use embassy_stm32::time::Hertz;
    let mut c = embassy_stm32::Config::default();
    c.rcc.hse = Some(Hse {
        freq: Hertz(HSE_HZ),
        mode: HseMode::Oscillator,
    });
    c.rcc.pll_src = PllSource::HSE;
    c.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL168,
        divp: Some(PllPDiv::DIV2),
        divq: Some(PllQDiv::DIV7),
        divr: None,
    });
    c.rcc.ahb_pre = AHBPrescaler::DIV1;
    c.rcc.apb1_pre = APBPrescaler::DIV4;
    c.rcc.apb2_pre = APBPrescaler::DIV2;
    c.rcc.sys = Sysclk::PLL1_P;
    c.rcc.mux.clk48sel = mux::Clk48sel::PLL1_Q;
    c
}

/// Start the chip with the board's clock tree ([`config`]); the peripherals.
#[cfg(target_os = "none")]
pub fn init() -> embassy_stm32::Peripherals {
    let p = embassy_stm32::init(config());
    // The G0B1: embassy sets the flash wait states (2 at 64 MHz) but leaves the prefetch
    // buffer at its reset value, off; turn it on, and the instruction cache (on at reset).
    #[cfg(feature = "board-g0b1")]
    embassy_stm32::pac::FLASH.acr().modify(|w| {
        w.set_prften(true);
        w.set_icen(true);
    });
    p
}

/// The firmware's SRAM contents (`$t`, a struct of byte arrays: DMA banks, scene banks),
/// placed in `.sram` (see memory.x), zeroed in place and returned as `&'static mut $t`.
///
/// Expands to a `static` of its own, so each expansion is one region; call it once, from
/// `main` (the expansion is not re-entrant: a second run of the same expansion would alias).
/// Zeroing goes through the raw pointer (no stack temporary: the banks are up to 120 KB),
/// which makes every byte array valid.
#[macro_export]
macro_rules! take_sram {
    ($t:ty) => {{
        #[link_section = ".sram"]
        static mut SRAM: core::mem::MaybeUninit<$t> = core::mem::MaybeUninit::uninit();
        // SAFETY: runs once (see the macro's doc): the only reference ever made to SRAM.
        // All-zero bytes are a valid `$t` (byte arrays).
        unsafe {
            let ptr = core::ptr::addr_of_mut!(SRAM).cast::<$t>();
            ptr.write_bytes(0, 1);
            &mut *ptr
        }
    }};
}
