//! NC bring-up: clocks, pins, the link task (interrupt executor, preempts rendering) and the
//! node task (thread mode: `links_core::node::run_node` with the build's kernels,
//! `nc_fw::Renderer`: f32 on the F407's FPU, Q16.16 on the F207).
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "nc-fw is firmware for the STM32F407VG: \
         cargo run --release --target thumbv7em-none-eabihf -p nc-fw \
         (NUCLEO-F207ZG: --target thumbv7m-none-eabi --no-default-features --features board-f207)"
    );
    std::process::exit(2);
}

#[cfg(target_os = "none")]
mod fw {
    use cortex_m_rt::entry;
    use defmt::{info, unwrap, warn};
    use embassy_executor::{Executor, InterruptExecutor};
    use embassy_stm32::exti::ExtiInput;
    use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};
    use embassy_stm32::interrupt;
    use embassy_stm32::interrupt::{InterruptExt, Priority};
    use embassy_stm32::peripherals::{DMA1_CH5, DMA1_CH6, USART2};
    use embassy_stm32::usart::{self, Uart};
    use embassy_stm32::{bind_interrupts, dma};
    use links_board::rs485::Rs485;
    use links_core::backup::{self, BackupNode, FrameReader};
    use links_core::board::Memory;
    use links_core::node::{run_node, NodeConfig, NodeReport, RealTime};
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
    static BACKUP_NODE: StaticCell<BackupNode<'static>> = StaticCell::new();

    bind_interrupts!(struct BackupIrqs {
        USART2 => usart::InterruptHandler<USART2>;
        DMA1_STREAM5 => dma::InterruptHandler<DMA1_CH5>;
        DMA1_STREAM6 => dma::InterruptHandler<DMA1_CH6>;
    });
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

    /// The serial backup line: answer the RC (roll call, health, polls) with
    /// `links_core::backup`'s node state. The node takes no scene over the line yet (its
    /// banks are the render task's): scene chunks are refused and counted.
    #[embassy_executor::task]
    async fn backup_task(mut line: Rs485, node: &'static mut BackupNode<'static>) {
        let mut reader = FrameReader::new();
        loop {
            if let Err(e) = backup::serve(&mut line, node, &mut reader).await {
                warn!("backup line: {}", e);
                reader.reset();
            }
        }
    }

    #[embassy_executor::task]
    async fn node_task(
        shared: &'static SlaveShared<'static>,
        even: &'static mut [u8],
        odd: &'static mut [u8],
    ) {
        let mut renderer = nc_fw::Renderer::default();
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
        #[cfg(not(feature = "board-f207"))]
        core::mem::forget(Output::new(p.PE3, Level::High, Speed::Low));
        // The board's pins that differ (nc_fw::pins): chip-select sense, backup line.
        #[cfg(not(feature = "board-f207"))]
        let (cs_sense, (line_tx, line_rx, line_de)) = (p.PB0, (p.PA2, p.PA3, p.PA1));
        #[cfg(feature = "board-f207")]
        let (cs_sense, (line_tx, line_rx, line_de)) = (p.PE0, (p.PD5, p.PD6, p.PD4));
        let port = NcPort {
            spi: p.SPI1,
            sck: p.PA5,
            miso: p.PA6,
            mosi: p.PA7,
            nss: p.PA4,
            tx_dma: p.DMA2_CH3,
            rx_dma: p.DMA2_CH0,
            cs: ExtiInput::new(cs_sense, p.EXTI0, Pull::Up, Irqs),
            ready: Output::new(p.PB1, Level::Low, Speed::VeryHigh),
            want_ready: false,
        };

        // The backup line (USART2, driver enable; nc_fw::pins::BACKUP) and the address straps.
        let straps = [
            Input::new(p.PE7, Pull::Up),
            Input::new(p.PE8, Pull::Up),
            Input::new(p.PE9, Pull::Up),
            Input::new(p.PE10, Pull::Up),
            Input::new(p.PE11, Pull::Up),
            Input::new(p.PE12, Pull::Up),
        ];
        let addr = nc_fw::backup_address(straps.each_ref().map(|s| s.is_low()));
        info!("backup line address {}", addr);
        let uart = unwrap!(Uart::new(
            p.USART2,
            line_rx,
            line_tx,
            p.DMA1_CH6,
            p.DMA1_CH5,
            BackupIrqs,
            links_board::rs485::config(),
        ));
        let line = Rs485 {
            uart,
            de: Output::new(line_de, Level::Low, Speed::VeryHigh),
        };
        let backup_node = BACKUP_NODE.init(BackupNode::new(addr, &mut []));

        interrupt::UART4.set_priority(Priority::P6);
        let spawner = EXECUTOR_LINK.start(interrupt::UART4);
        spawner.spawn(unwrap!(link_task(port, task, shared)));
        spawner.spawn(unwrap!(backup_task(line, backup_node)));

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
