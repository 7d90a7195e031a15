//! NC bring-up: clocks, pins, the link task (interrupt executor, preempts rendering) and the
//! node task (thread mode: `links_core::node::run_node` with the build's kernels,
//! `nc_fw::Renderer`: f32 on the F407's FPU, Q16.16 on the F207 and the G0B1).
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "nc-fw is firmware for the STM32F407VG: \
         cargo run --release --target thumbv7em-none-eabihf -p nc-fw \
         (NUCLEO-F207ZG: --target thumbv7m-none-eabi --no-default-features --features board-f207; \
         NUCLEO-G0B1RE: --target thumbv6m-none-eabi --no-default-features --features board-g0b1)"
    );
    std::process::exit(2);
}

#[cfg(target_os = "none")]
mod fw {
    use core::cell::RefCell;
    use cortex_m_rt::entry;
    use defmt::{info, unwrap, warn};
    use embassy_executor::{Executor, InterruptExecutor};
    use embassy_futures::select::{select, Either};
    use embassy_stm32::exti::ExtiInput;
    use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};
    use embassy_stm32::interrupt;
    use embassy_stm32::interrupt::{InterruptExt, Priority};
    #[cfg(feature = "board-g0b1")]
    use embassy_stm32::peripherals::{DMA1_CH4, DMA1_CH5, USART1};
    #[cfg(not(feature = "board-g0b1"))]
    use embassy_stm32::peripherals::{DMA1_CH5, DMA1_CH6, USART2};
    use embassy_stm32::usart::{self, Uart};
    use embassy_stm32::{bind_interrupts, dma};
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
    use embassy_sync::blocking_mutex::Mutex;
    use embassy_sync::signal::Signal;
    use embassy_time::{Instant, Timer};
    use links_board::rs485::Rs485;
    use links_core::backup::{
        self, BackupNode, BackupRender, BackupRenderError, FrameReader, Piece,
    };
    use links_core::board::Memory;
    use links_core::node::{
        restore_lent, run_node_landing, NodeConfig, NodeReport, RealTime, RunRenderer,
    };
    use links_core::render::Rgb8;
    use links_core::spi::{Bank, SlaveBanks, SlaveShared, SlaveTask};
    use nc_fw::backup_line::{IDLE_MS, PIECE};
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
    /// The node's backup-line state: the line task answers with it (interrupt executor),
    /// the node task renders its jobs (thread mode); each holds it for one step at a time.
    type Backup = Mutex<CriticalSectionRawMutex, RefCell<BackupNode<'static>>>;
    static BACKUP_NODE: StaticCell<Backup> = StaticCell::new();
    /// Raised by the line task when the RC sends work or a scene over the line: the RC
    /// declared the SPI link dead, so the node task lends the line its even bank.
    static WANT_BANK: Signal<CriticalSectionRawMutex, ()> = Signal::new();

    #[cfg(not(feature = "board-g0b1"))]
    bind_interrupts!(struct BackupIrqs {
        USART2 => usart::InterruptHandler<USART2>;
        DMA1_STREAM5 => dma::InterruptHandler<DMA1_CH5>;
        DMA1_STREAM6 => dma::InterruptHandler<DMA1_CH6>;
    });
    // The G0B1: USART1 with DMA1 channels 4 (TX) and 5 (RX), whose interrupt line the G0
    // shares among DMA1 channels 4-7 and DMA2's.
    #[cfg(feature = "board-g0b1")]
    bind_interrupts!(struct BackupIrqs {
        USART1 => usart::InterruptHandler<USART1>;
        DMA1_CH4_7_DMA2_CH1_5_DMAMUX1_OVR =>
            dma::InterruptHandler<DMA1_CH4>, dma::InterruptHandler<DMA1_CH5>;
    });
    static EXECUTOR_LINK: InterruptExecutor = InterruptExecutor::new();
    static EXECUTOR_NODE: StaticCell<Executor> = StaticCell::new();

    /// The link executor's interrupt: one of a peripheral the board does not use (UART4 on
    /// the F4 and F2 boards).
    #[cfg(not(feature = "board-g0b1"))]
    #[interrupt]
    unsafe fn UART4() {
        // SAFETY: the interrupt executor's documented use: called from its own interrupt.
        unsafe { EXECUTOR_LINK.on_interrupt() }
    }
    /// The link executor's interrupt on the G0B1: USART3-6's and LPUART1's shared line (none
    /// of them used).
    #[cfg(feature = "board-g0b1")]
    #[interrupt]
    unsafe fn USART3_4_5_6_LPUART1() {
        // SAFETY: the interrupt executor's documented use: called from its own interrupt.
        unsafe { EXECUTOR_LINK.on_interrupt() }
    }
    #[cfg(not(feature = "board-g0b1"))]
    use interrupt::UART4 as LINK_IRQ;
    #[cfg(feature = "board-g0b1")]
    use interrupt::USART3_4_5_6_LPUART1 as LINK_IRQ;
    /// The link executor's priority: above thread mode (the node task), below embassy's
    /// drivers (priority 0): 6 of the F4's and F2's 16 levels, 2 of the G0's 4.
    #[cfg(not(feature = "board-g0b1"))]
    const LINK_PRIORITY: Priority = Priority::P6;
    #[cfg(feature = "board-g0b1")]
    const LINK_PRIORITY: Priority = Priority::P2;

    #[embassy_executor::task]
    async fn link_task(
        port: NcPort,
        task: SlaveTask<'static>,
        shared: &'static SlaveShared<'static>,
    ) {
        let mut port = port;
        task.run(&mut port, shared).await
    }

    /// The serial backup line: answer the RC (roll call, health, scene, work, polls) with
    /// `links_core::backup`'s node state, one frame at a time under its lock.
    #[embassy_executor::task]
    async fn backup_task(mut line: Rs485, node: &'static Backup) {
        let mut reader = FrameReader::new();
        loop {
            let served = backup::serve_with(&mut line, &mut reader, |frame, reply| {
                node.lock(|n| {
                    let mut n = n.borrow_mut();
                    let r = n.handle(frame, reply);
                    if n.take_bank_request() {
                        WANT_BANK.signal(());
                    }
                    r
                })
            });
            if let Err(e) = served.await {
                warn!("backup line: {}", e);
                reader.reset();
            }
        }
    }

    /// The node served over the backup line (its SPI link dead): lend the line the even
    /// bank, render the jobs that arrive with the SPI path's tracer, piece by piece (the
    /// bank taken out of the shared state while a piece renders, so the line task answers
    /// meanwhile), until the line has had nothing for the node for [`IDLE_MS`].
    async fn serve_line(
        node: &'static Backup,
        even: &mut &'static mut [u8],
        renderer: &mut nc_fw::Renderer,
    ) {
        let bank = core::mem::take(even);
        node.lock(|n| n.borrow_mut().lend_bank(bank));
        let mut work = BackupRender::new();
        let mut px = [Rgb8::default(); PIECE];
        let mut last_work = Instant::now();
        loop {
            type Step = Result<Option<(Piece, usize, &'static mut [u8])>, BackupRenderError>;
            let step: Step = node.lock(|n| {
                let mut n = n.borrow_mut();
                let piece = work.next(&mut n, PIECE)?;
                let len = n.scene.ready().map_or(0, |s| s.1.len());
                Ok(piece.map(|p| (p, len, n.take_bank())))
            });
            match step {
                Ok(Some((piece, len, bank))) => {
                    let scene = bank.get(..len).unwrap_or_default();
                    let r = work.render(&piece, scene, renderer, &mut px);
                    let done = node.lock(|n| {
                        let mut n = n.borrow_mut();
                        n.lend_bank(bank);
                        r.and_then(|_| work.finish(&mut n, &piece, &px))
                    });
                    if let Err(e) = done {
                        warn!("backup line: {}", e);
                        Timer::after_millis(1).await;
                    }
                    last_work = Instant::now();
                }
                Ok(None) if work.job().is_none() && last_work.elapsed().as_millis() > IDLE_MS => {
                    *even = node.lock(|n| n.borrow_mut().take_bank());
                    WANT_BANK.reset();
                    return;
                }
                Ok(None) => Timer::after_millis(1).await,
                Err(e) => {
                    warn!("backup line: {}", e);
                    Timer::after_millis(1).await;
                }
            }
        }
    }

    #[embassy_executor::task]
    async fn node_task(
        shared: &'static SlaveShared<'static>,
        even: &'static mut [u8],
        odd: &'static mut [u8],
        backup: &'static Backup,
    ) {
        let mut renderer = nc_fw::Renderer::default();
        let mut link = shared.handle();
        let mut clock = RealTime;
        // Frame f's scene in bank f % 2; while a run renders from one, the other is lent to
        // the link task, which writes broadcast scene chunks straight into it.
        let mut banks: [&'static mut [u8]; 2] = [even, odd];
        loop {
            let mut report = NodeReport::default();
            let parts = (&mut link, shared, &mut clock, &mut renderer);
            let spi = run_node_landing(NodeConfig::default(), parts, &mut banks, &mut report);
            let ended = select(spi, WANT_BANK.wait()).await;
            // A bank still lent when the node logic was dropped comes back first.
            restore_lent(shared, &mut banks);
            match ended {
                Either::First(Ok(())) => info!("stopped: {}", report),
                Either::First(Err(e)) => warn!("node error {}: {}", e, report),
                Either::Second(()) => {
                    info!("backup line: the RC serves this node over the line");
                    serve_line(backup, &mut banks[0], &mut renderer).await;
                    // The even bank now holds the line's scene: no cache from it survives.
                    renderer.forget();
                    info!("backup line: back to SPI");
                }
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
        #[cfg(feature = "board-f407")]
        core::mem::forget(Output::new(p.PE3, Level::High, Speed::Low));
        // The board's pins that differ (nc_fw::pins): SPI1 and its DMA, chip-select sense,
        // backup line, address straps.
        #[cfg(not(feature = "board-g0b1"))]
        let (sck, miso, mosi, tx_dma, rx_dma) = (p.PA5, p.PA6, p.PA7, p.DMA2_CH3, p.DMA2_CH0);
        #[cfg(feature = "board-g0b1")]
        let (sck, miso, mosi, tx_dma, rx_dma) = (p.PB3, p.PB4, p.PB5, p.DMA1_CH2, p.DMA1_CH1);
        #[cfg(feature = "board-f407")]
        let (cs_sense, (line_tx, line_rx, line_de)) = (p.PB0, (p.PA2, p.PA3, p.PA1));
        #[cfg(feature = "board-f207")]
        let (cs_sense, (line_tx, line_rx, line_de)) = (p.PE0, (p.PD5, p.PD6, p.PD4));
        #[cfg(feature = "board-g0b1")]
        let (cs_sense, (line_tx, line_rx, line_de)) = (p.PB0, (p.PC4, p.PC5, p.PA1));
        #[cfg(not(feature = "board-g0b1"))]
        let (straps, line_uart, (line_tx_dma, line_rx_dma)) = (
            (p.PE7, p.PE8, p.PE9, p.PE10, p.PE11, p.PE12),
            p.USART2,
            (p.DMA1_CH6, p.DMA1_CH5),
        );
        #[cfg(feature = "board-g0b1")]
        let (straps, line_uart, (line_tx_dma, line_rx_dma)) = (
            (p.PC0, p.PC1, p.PC2, p.PC3, p.PC6, p.PC8),
            p.USART1,
            (p.DMA1_CH4, p.DMA1_CH5),
        );
        let port = NcPort {
            spi: p.SPI1,
            sck,
            miso,
            mosi,
            nss: p.PA4,
            tx_dma,
            rx_dma,
            cs: ExtiInput::new(cs_sense, p.EXTI0, Pull::Up, Irqs),
            ready: Output::new(p.PB1, Level::Low, Speed::VeryHigh),
            want_ready: false,
        };

        // The backup line (its UART, driver enable; nc_fw::pins::BACKUP) and the address
        // straps.
        let straps = [
            Input::new(straps.0, Pull::Up),
            Input::new(straps.1, Pull::Up),
            Input::new(straps.2, Pull::Up),
            Input::new(straps.3, Pull::Up),
            Input::new(straps.4, Pull::Up),
            Input::new(straps.5, Pull::Up),
        ];
        let addr = nc_fw::backup_address(straps.each_ref().map(|s| s.is_low()));
        info!("backup line address {}", addr);
        let uart = unwrap!(Uart::new(
            line_uart,
            line_rx,
            line_tx,
            line_tx_dma,
            line_rx_dma,
            BackupIrqs,
            links_board::rs485::config(),
        ));
        let line = Rs485 {
            uart,
            de: Output::new(line_de, Level::Low, Speed::VeryHigh),
        };
        // No bank until the RC serves the node over the line (then the even one).
        let backup_node: &'static Backup =
            BACKUP_NODE.init(Mutex::new(RefCell::new(BackupNode::new(addr, &mut []))));

        LINK_IRQ.set_priority(LINK_PRIORITY);
        let spawner = EXECUTOR_LINK.start(LINK_IRQ);
        spawner.spawn(unwrap!(link_task(port, task, shared)));
        spawner.spawn(unwrap!(backup_task(line, backup_node)));

        let executor = EXECUTOR_NODE.init(Executor::new());
        // The odd bank is wherever the plan put it (the other placement is empty).
        let odd: &'static mut [u8] = if BOARD.odd_bank_in == Memory::Sram {
            scene_odd
        } else {
            SCENE_ODD_BANK.take()
        };
        executor.run(|s| s.spawn(unwrap!(node_task(shared, scene_even, odd, backup_node))))
    }
}
