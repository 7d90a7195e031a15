//! The relay role (`cargo build -p rc-fw --features relay`): a node on its parent's bus and
//! the root of a bus of 8 NCs of its own (`links_core::relay::run_relay`; docs/hardware.md,
//! "Reaching 64 and 256 nodes"). SPI1 is a slave towards the parent through `nc-fw`'s port
//! (the NC board's pins and DMA2 streams 0 and 3), SPI2 the master of the relay's bus
//! (`rc_fw::port::RcPort`, DMA1 streams 3 and 4) from the relay pin table
//! (`rc_fw::with_relay_pins!`). Both link tasks run on an interrupt executor (UART4's
//! interrupt, priority 6) above the thread executor where the relay logic runs. No USB, no
//! scene: a relay stores and forwards. The backup line is not run on a relay.
//!
//! A middle relay of a two-level tree (`--features relay-mid`) runs the same logic with
//! leaf relays as its bus devices ([`BUS_DEVICES`]): `run_relay` over a `RelayedBus` on
//! SPI2, its buffers in SRAM, each node exchange given up after
//! `links_core::relay::MID_RELAY_TIMEOUT_US` (below the root's time-out), or, begun ahead of
//! its node's line, after the node's silence bound besides.
//!
//! A leaf relay keeps a reply cell per NC for replies the root of two levels sends ahead of
//! the node's line (`RelayBuffers::ahead`): the NC is clocked with it the moment its line
//! rises.

use defmt::{info, unwrap, warn};
use embassy_executor::{InterruptExecutor, Spawner};
use embassy_stm32::exti::{self, ExtiInput};
use embassy_stm32::gpio::{Level, Output, Pull, Speed};
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::peripherals::{DMA1_CH3, DMA1_CH4};
use embassy_stm32::spi::{self, Spi};
use embassy_stm32::time::Hertz;
use embassy_stm32::{bind_interrupts, dma, interrupt};
use links_core::link::RootBus;
use links_core::relay::{run_relay, RelayBuffers, REPLY_CELL};
use links_core::spi::{
    Bank, MasterFront, MasterShared, MasterTask, SlaveBanks, SlaveShared, SlaveTask,
};
use links_core::wire::MAX_MESSAGE;
use nc_fw::port::NcPort;
use rc_fw::pins::NODES;
use rc_fw::port::RcPort;
use static_cell::StaticCell;
use {defmt_rtt as _, panic_probe as _};

bind_interrupts!(struct Irqs {
    DMA1_STREAM3 => dma::InterruptHandler<DMA1_CH3>;
    DMA1_STREAM4 => dma::InterruptHandler<DMA1_CH4>;
    EXTI1 => exti::InterruptHandler<interrupt::typelevel::EXTI1>;
    EXTI2 => exti::InterruptHandler<interrupt::typelevel::EXTI2>;
    EXTI3 => exti::InterruptHandler<interrupt::typelevel::EXTI3>;
    EXTI9_5 => exti::InterruptHandler<interrupt::typelevel::EXTI9_5>;
    EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
});

/// The devices on the relay's bus: its NCs, or as a middle relay (`relay-mid`) the leaf
/// relays whose nodes its report to the root has bits for (4 of 8 NCs).
const BUS_DEVICES: usize = if cfg!(feature = "relay-mid") {
    (links_core::relay::MAX_RELAY_NODES as usize) / NODES
} else {
    NODES
};
const _: () = assert!(BUS_DEVICES >= 1 && BUS_DEVICES <= NODES);

/// Everything DMA touches (`.sram`): the parent link's five banks, the bus's three; and the
/// relay's three frame buffers (a middle relay's `RelayedBus` buffers too).
struct Sram {
    parent: [Bank; 5],
    bus: [Bank; 3],
    relay: [[u8; MAX_MESSAGE]; 3],
    /// A leaf relay's reply cell per NC, for replies sent ahead.
    #[cfg(not(feature = "relay-mid"))]
    ahead: [[u8; REPLY_CELL]; NODES],
    /// A middle relay's `RelayedBus` buffers: a reply cell for each node behind it.
    #[cfg(feature = "relay-mid")]
    leaves: links_core::relay::RelayedFrames<{ links_core::relay::MID_SLOTS }>,
}

static BUS: MasterShared<'static> = MasterShared::new();
static PARENT: StaticCell<SlaveShared<'static>> = StaticCell::new();
static EXECUTOR_LINKS: InterruptExecutor = InterruptExecutor::new();

#[interrupt]
unsafe fn UART4() {
    // SAFETY: the interrupt executor's documented use: called from its own interrupt.
    unsafe { EXECUTOR_LINKS.on_interrupt() }
}

/// The parent's link (`links_core::spi::SlaveTask` over `nc-fw`'s SPI1 slave port).
#[embassy_executor::task]
async fn parent_task(
    port: NcPort,
    task: SlaveTask<'static>,
    shared: &'static SlaveShared<'static>,
) {
    let mut port = port;
    task.run(&mut port, shared).await
}

/// The relay's own bus (`links_core::spi::MasterTask` over SPI2).
#[embassy_executor::task]
async fn bus_task(port: RcPort<NODES>) {
    let mut port = port;
    MasterTask::new().run(&mut port, &BUS).await
}

/// Relay one render after another over `bus` (each ends with the root's `Stop`).
async fn relay_forever<B: RootBus>(
    parent: &'static SlaveShared<'static>,
    bus: &mut B,
    bufs: &'static mut [[u8; MAX_MESSAGE]; 3],
    ahead: &'static mut [[u8; REPLY_CELL]],
) {
    let mut handle = parent.handle();
    loop {
        let [down, up, node] = &mut *bufs;
        let buffers = RelayBuffers {
            down,
            up,
            node,
            ahead: &mut *ahead,
        };
        match run_relay(&mut handle, bus, buffers).await {
            Ok(r) => info!("relayed: {}", r),
            Err(e) => warn!("relay: {}", e),
        }
    }
}

/// The relay logic over its bus of NCs.
#[cfg(not(feature = "relay-mid"))]
#[embassy_executor::task]
async fn relay_task(
    parent: &'static SlaveShared<'static>,
    mut bus: MasterFront<'static, 'static>,
    bufs: &'static mut [[u8; MAX_MESSAGE]; 3],
    ahead: &'static mut [[u8; REPLY_CELL]; NODES],
) {
    relay_forever(parent, &mut bus, bufs, ahead).await
}

/// As a middle relay: the bus's devices are leaf relays, driven through a `RelayedBus`.
#[cfg(feature = "relay-mid")]
#[embassy_executor::task]
async fn relay_task(
    parent: &'static SlaveShared<'static>,
    bus: MasterFront<'static, 'static>,
    bufs: &'static mut [[u8; MAX_MESSAGE]; 3],
    leaves: &'static mut links_core::relay::RelayedFrames<{ links_core::relay::MID_SLOTS }>,
) {
    use links_core::relay::{RelayedBus, MID_RELAY_TIMEOUT_US, MID_SLOTS};
    match RelayedBus::new(bus, leaves, 0, NODES as u16) {
        Ok(b) => {
            // An exchange in flight for every node behind it: the root sends replies ahead,
            // and they wait at the leaf relays while the nodes render (as long as a node
            // may be silent).
            let mut leaves = b
                .with_slots::<MID_SLOTS>()
                .with_timeout(rc_fw::port::Clock, MID_RELAY_TIMEOUT_US)
                .with_ahead(rc_fw::link::PROFILE.node_timeout_us)
                .with_depth(NODES as u16);
            relay_forever(parent, &mut leaves, bufs, &mut []).await
        }
        Err(e) => warn!("middle relay: {}", e),
    }
}

/// Wire the relay's bus from the relay pin table (`rc_fw::with_relay_pins!`).
macro_rules! wire_bus {
    ($p:ident, $cfg:ident;
     parent: [$($par:ident),*], cs_sense: $sense:ident / $sexti:ident, ready_out: $rdy_out:ident,
     spi2: [$sck:ident, $miso:ident, $mosi:ident], accel_cs: $acc:ident,
     cs: [$($cs:ident),*], ready: [$($rdy:ident / $exti:ident),*],
     miso_sel: [$($sel:ident),*]) => {{
        let spi = Spi::new(
            $p.SPI2, $p.$sck, $p.$mosi, $p.$miso, $p.DMA1_CH4, $p.DMA1_CH3, Irqs, $cfg,
        );
        let cs = [$(Output::new($p.$cs, Level::High, Speed::VeryHigh)),*];
        let ready = [$(ExtiInput::new($p.$rdy, $p.$exti, Pull::Down, Irqs)),*];
        let miso_sel = [$(Output::new($p.$sel, Level::Low, Speed::VeryHigh)),*];
        let bus = RcPort { spi, cs, ready, miso_sel };
        let accel_cs = Output::new($p.$acc, Level::High, Speed::Low);
        core::mem::forget(accel_cs);
        let parent = NcPort {
            spi: $p.SPI1,
            sck: $p.PA5,
            miso: $p.PA6,
            mosi: $p.PA7,
            nss: $p.PA4,
            tx_dma: $p.DMA2_CH3,
            rx_dma: $p.DMA2_CH0,
            cs: ExtiInput::new($p.$sense, $p.$sexti, Pull::Up, nc_fw::port::Irqs),
            ready: Output::new($p.$rdy_out, Level::Low, Speed::VeryHigh),
            want_ready: false,
        };
        (parent, bus)
    }};
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = links_board::init();
    info!("LINKS-1 relay RC up");
    // `main` runs once, so this expansion does: the only reference to the region.
    let sram: &'static mut Sram = links_board::take_sram!(Sram);
    #[cfg(not(feature = "relay-mid"))]
    let Sram {
        parent,
        bus,
        relay,
        ahead,
    } = sram;
    #[cfg(feature = "relay-mid")]
    let Sram {
        parent,
        bus,
        relay,
        leaves,
    } = sram;

    let mut spi_cfg = spi::Config::default();
    spi_cfg.frequency = Hertz(rc_fw::link::SPI_HZ);
    spi_cfg.mode = spi::MODE_0;
    let (parent_port, bus_port) = rc_fw::with_relay_pins!(wire_bus, p, spi_cfg);

    let [tx0, tx1, rx0, rx1, scratch] = parent;
    let (shared, task) = SlaveShared::new(SlaveBanks {
        tx: [tx0, tx1],
        rx: [rx0, rx1],
        scratch,
    });
    let shared: &'static SlaveShared<'static> = PARENT.init(shared);
    let [btx0, btx1, brx] = bus;
    let front = MasterFront::new(&BUS, 0, BUS_DEVICES as u16, [btx0, btx1], brx);

    interrupt::UART4.set_priority(Priority::P6);
    let links = EXECUTOR_LINKS.start(interrupt::UART4);
    links.spawn(unwrap!(parent_task(parent_port, task, shared)));
    links.spawn(unwrap!(bus_task(bus_port)));
    #[cfg(not(feature = "relay-mid"))]
    spawner.spawn(unwrap!(relay_task(shared, front, relay, ahead)));
    #[cfg(feature = "relay-mid")]
    spawner.spawn(unwrap!(relay_task(shared, front, relay, leaves)));
}
