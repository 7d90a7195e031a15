//! NC bring-up: clocks, pins, the link task (interrupt executor, preempts rendering) and the
//! node task (thread mode: `links_core::node::run_node`, rendering f32 on the FPU).
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "nc-fw is firmware for the STM32F407VG: \
         cargo run --release --target thumbv7em-none-eabihf -p nc-fw"
    );
    std::process::exit(2);
}

#[cfg(target_os = "none")]
mod fw {
    use cortex_m_rt::entry;
    use defmt::{info, unwrap, warn};
    use embassy_executor::{Executor, InterruptExecutor};
    use embassy_stm32::exti::ExtiInput;
    use embassy_stm32::gpio::{Level, Output, Pull, Speed};
    use embassy_stm32::interrupt;
    use embassy_stm32::interrupt::{InterruptExt, Priority};
    use links_core::board::Memory;
    use links_core::node::{run_node, NodeConfig, NodeReport, RealTime, Tracing};
    use links_core::spi::{Bank, SlaveBanks, SlaveShared, SlaveTask};
    use nc_fw::plan::{BOARD, SCENE_EVEN, SCENE_ODD_CCM, SCENE_ODD_SRAM};
    use nc_fw::port::{Irqs, NcPort};
    use static_cell::{ConstStaticCell, StaticCell};
    use {defmt_rtt as _, panic_probe as _};

    /// Everything DMA touches, and the scene banks placed in SRAM (`.sram`, see memory.x).
    struct Sram {
        link: [Bank; 5],
        scene_even: [u8; SCENE_EVEN],
        /// The odd frames' bank when the plan puts it in SRAM (else empty).
        scene_odd: [u8; SCENE_ODD_SRAM],
    }

    /// The odd frames' scene bank when the plan puts it in CCM (`.bss`; else empty), read in
    /// place by the CPU only.
    static SCENE_ODD_BANK: ConstStaticCell<[u8; SCENE_ODD_CCM]> =
        ConstStaticCell::new([0; SCENE_ODD_CCM]);
    static SHARED: StaticCell<SlaveShared<'static>> = StaticCell::new();
    static EXECUTOR_LINK: InterruptExecutor = InterruptExecutor::new();
    static EXECUTOR_NODE: StaticCell<Executor> = StaticCell::new();

    #[interrupt]
    unsafe fn UART4() {
        // SAFETY: the interrupt executor's documented use: called from its own interrupt.
        unsafe { EXECUTOR_LINK.on_interrupt() }
    }

    #[embassy_executor::task]
    async fn link_task(
        port: NcPort,
        task: SlaveTask<'static>,
        shared: &'static SlaveShared<'static>,
    ) {
        let mut port = port;
        task.run(&mut port, shared).await
    }

    #[embassy_executor::task]
    async fn node_task(
        shared: &'static SlaveShared<'static>,
        even: &'static mut [u8],
        odd: &'static mut [u8],
    ) {
        let mut renderer = Tracing::<f32>::new();
        let mut link = shared.handle();
        loop {
            let mut report = NodeReport::default();
            let r = run_node(
                NodeConfig::default(),
                &mut link,
                &mut RealTime,
                &mut renderer,
                [&mut *even, &mut *odd],
                &mut report,
            )
            .await;
            match r {
                Ok(()) => info!("stopped: {}", report),
                Err(e) => warn!("node error {}: {}", e, report),
            }
            info!("link: {}", shared.counters());
        }
    }

    #[entry]
    fn main() -> ! {
        let p = links_board::init();
        info!("LINKS-1 NC up");
        // `main` runs once, so this expansion does: the only reference to the region.
        let sram: &'static mut Sram = links_board::take_sram!(Sram);
        let Sram {
            link,
            scene_even,
            scene_odd,
        } = sram;
        let [tx0, tx1, rx0, rx1, scratch] = link;
        let (shared, task) = SlaveShared::new(SlaveBanks {
            tx: [tx0, tx1],
            rx: [rx0, rx1],
            scratch,
        });
        let shared: &'static SlaveShared<'static> = SHARED.init(shared);

        // The Discovery's accelerometer shares SPI1's pins: keep it deselected.
        let accel_cs = Output::new(p.PE3, Level::High, Speed::Low);
        core::mem::forget(accel_cs);
        let port = NcPort {
            spi: p.SPI1,
            sck: p.PA5,
            miso: p.PA6,
            mosi: p.PA7,
            nss: p.PA4,
            tx_dma: p.DMA2_CH3,
            rx_dma: p.DMA2_CH0,
            cs: ExtiInput::new(p.PB0, p.EXTI0, Pull::Up, Irqs),
            ready: Output::new(p.PB1, Level::Low, Speed::VeryHigh),
            want_ready: false,
        };

        interrupt::UART4.set_priority(Priority::P6);
        let spawner = EXECUTOR_LINK.start(interrupt::UART4);
        spawner.spawn(unwrap!(link_task(port, task, shared)));

        let executor = EXECUTOR_NODE.init(Executor::new());
        // The odd bank is wherever the plan put it (the other placement is empty).
        let odd: &'static mut [u8] = if BOARD.odd_bank_in == Memory::Sram {
            scene_odd
        } else {
            SCENE_ODD_BANK.take()
        };
        executor.run(|s| s.spawn(unwrap!(node_task(shared, scene_even, odd))))
    }
}
