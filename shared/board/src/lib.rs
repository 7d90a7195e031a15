//! The board both LINKS-1 firmwares run on (STM32F407VG on an STM32F4DISCOVERY): the RAM
//! sizes their memory plans divide up, and for the MCU the one bring-up they share: the
//! clock tree ([`config`], [`init`]) and the zeroed DMA-reachable `.sram` region
//! ([`take_sram!`]), and the serial backup line's RS-485 port (`rs485`). Pins and memory plans stay with each firmware (`nc-fw`, `rc-fw`).
#![no_std]

#[cfg(target_os = "none")]
pub mod rs485;

/// SRAM1 + SRAM2 (DMA-reachable): the board's data, `links_core::board::NodeBoard::F407`.
pub const SRAM: usize = links_core::board::NodeBoard::F407.sram;
/// CCM data RAM (CPU only): the board's data, `links_core::board::NodeBoard::F407`.
pub const CCM: usize = links_core::board::NodeBoard::F407.ccm;

/// The core clock the clock tree below gives: the board profile's
/// (`links_core::board::BoardProfile::F407`).
pub const CORE_CLOCK_HZ: u32 = links_core::board::BoardProfile::F407.core_clock_hz;
/// The crystal.
pub const HSE_HZ: u32 = 8_000_000;
// The PLL of [`config`]: HSE / 4 (prediv) x 168 (mul) / 2 (P) must give the profile's clock.
const _: () = assert!(HSE_HZ / 4 * 168 / 2 == CORE_CLOCK_HZ);

/// The clock tree: 8 MHz crystal -> 168 MHz core, APB2 84 MHz (SPI1 up to 42 MHz), 48 MHz
/// for USB.
#[cfg(target_os = "none")]
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
    embassy_stm32::init(config())
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
