//! RC bring-up: clocks, USB CDC (scene upload, frame readback: `links_core::serial`), the SPI
//! star (chip-selects, handshake EXTI) and `links_core::root::run_bus` over it. The bus is
//! clocked by `links_core::spi::MasterTask` on an interrupt executor (UART4's IRQ, priority
//! 6) while `run_bus` and USB run on the thread executor: the wire overlaps the RC's work.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "rc-fw is firmware for the STM32F407VG: \
         cargo run --release --target thumbv7em-none-eabihf -p rc-fw \
         (NUCLEO-F207ZG: --target thumbv7m-none-eabi --no-default-features --features board-f207; \
         NUCLEO-G0B1RE: --target thumbv6m-none-eabi --no-default-features --features board-g0b1)"
    );
    std::process::exit(2);
}

/// The relay role (`--features relay`): see `relay_role.rs`.
#[cfg(all(target_os = "none", feature = "relay"))]
#[path = "relay_role.rs"]
mod relay_role;

#[cfg(all(target_os = "none", not(feature = "relay")))]
mod fw {
    use defmt::{info, unwrap, warn};
    use embassy_executor::{InterruptExecutor, Spawner};
    use embassy_futures::select::{select, Either};
    use embassy_stm32::exti::{self, ExtiInput};
    use embassy_stm32::gpio::{Level, Output, Pull, Speed};
    use embassy_stm32::interrupt::{InterruptExt, Priority};
    #[cfg(feature = "board-g0b1")]
    use embassy_stm32::peripherals::{DMA1_CH1, DMA1_CH2, DMA1_CH4, DMA1_CH5, USART1, USB};
    #[cfg(all(feature = "relay-root", feature = "board-f407"))]
    use embassy_stm32::peripherals::{DMA1_CH3, DMA1_CH4};
    #[cfg(not(feature = "board-g0b1"))]
    use embassy_stm32::peripherals::{DMA1_CH5, DMA1_CH6, DMA2_CH0, DMA2_CH3, USART2, USB_OTG_FS};
    use embassy_stm32::spi::{self, Spi};
    use embassy_stm32::time::Hertz;
    use embassy_stm32::usart::{self as uart, Uart};
    use embassy_stm32::{bind_interrupts, dma, interrupt, usb};
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
    use embassy_sync::mutex::Mutex;
    use embassy_sync::pipe::Pipe;
    use embassy_time::Timer;
    use embassy_usb::class::cdc_acm::{CdcAcmClass, Receiver, Sender, State};
    use embassy_usb::{Builder, UsbDevice};
    use links_board::rs485::Rs485;
    use links_core::backup::{self, PortLine};
    #[cfg(all(feature = "relay-root", not(feature = "board-f407")))]
    use links_core::relay::RelayedBuffers;
    #[cfg(feature = "relay-root")]
    use links_core::relay::RelayedBus;
    #[cfg(all(feature = "relay-root", feature = "board-f407"))]
    use links_core::relay::TwoLinks;
    use links_core::serial::film::bank_of;
    use links_core::serial::readback::ByteQueue;
    use links_core::serial::throttle::Room;
    use links_core::serial::{Encoder, FrameStreamer};
    use links_core::spi::{Bank, MasterFront, MasterShared, MasterTask};
    use rc_fw::backup_line::{REPLY_TIMEOUT_US, ROLL_CALL_NODES, ROLL_CALL_PERIOD_MS, SERVE};
    #[cfg(all(feature = "relay-root", feature = "board-f407"))]
    use rc_fw::link::LINK_NODES;
    use rc_fw::link::RENDER_NODE_SET;
    #[cfg(not(all(feature = "relay-root", feature = "board-f407")))]
    use rc_fw::pins::NODES;
    use rc_fw::plan::{FILM_BANK, SCENE};
    use rc_fw::port::{Clock, PipeQueue, RcPort, UsbPipe};
    use rc_fw::render::{render_film_frame, render_frames_with_line, reply_room, resend_span};
    use rc_fw::session::{Session, Step};
    use static_cell::{ConstStaticCell, StaticCell};
    use {defmt_rtt as _, panic_probe as _};

    #[cfg(not(feature = "board-g0b1"))]
    type UsbDriver = usb::Driver<'static, USB_OTG_FS>;
    /// The G0's USB device peripheral (not the F4's OTG core).
    #[cfg(feature = "board-g0b1")]
    type UsbDriver = usb::Driver<'static, USB>;
    /// The root logic's bus: the NCs on SPI1, or (feature `relay-root`) the nodes behind
    /// the relay RCs on SPI1 (and, on the F407, SPI2: relays 4..7, `TwoLinks`).
    #[cfg(not(feature = "relay-root"))]
    type Link = MasterFront<'static, 'static>;
    #[cfg(all(feature = "relay-root", not(feature = "board-f407")))]
    type Link = RelayedBus<'static, MasterFront<'static, 'static>, Clock>;
    /// Each link's state keeps `rc_fw::link::RELAY_SLOTS` exchanges in flight.
    #[cfg(all(feature = "relay-root", feature = "board-f407"))]
    type Relayed =
        RelayedBus<'static, MasterFront<'static, 'static>, Clock, { rc_fw::link::RELAY_SLOTS }>;
    #[cfg(all(feature = "relay-root", feature = "board-f407"))]
    type Link = TwoLinks<Relayed, Relayed>;

    #[cfg(not(feature = "board-g0b1"))]
    bind_interrupts!(struct Irqs {
        OTG_FS => usb::InterruptHandler<USB_OTG_FS>;
        DMA2_STREAM0 => dma::InterruptHandler<DMA2_CH0>;
        DMA2_STREAM3 => dma::InterruptHandler<DMA2_CH3>;
        EXTI0 => exti::InterruptHandler<interrupt::typelevel::EXTI0>;
        EXTI1 => exti::InterruptHandler<interrupt::typelevel::EXTI1>;
        EXTI2 => exti::InterruptHandler<interrupt::typelevel::EXTI2>;
        EXTI3 => exti::InterruptHandler<interrupt::typelevel::EXTI3>;
        EXTI9_5 => exti::InterruptHandler<interrupt::typelevel::EXTI9_5>;
        #[cfg(feature = "board-f207")]
        EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
        USART2 => uart::InterruptHandler<USART2>;
        DMA1_STREAM5 => dma::InterruptHandler<DMA1_CH5>;
        DMA1_STREAM6 => dma::InterruptHandler<DMA1_CH6>;
        #[cfg(all(feature = "relay-root", feature = "board-f407"))]
        DMA1_STREAM3 => dma::InterruptHandler<DMA1_CH3>;
        #[cfg(all(feature = "relay-root", feature = "board-f407"))]
        DMA1_STREAM4 => dma::InterruptHandler<DMA1_CH4>;
    });
    // The G0B1: USB (its interrupt shared with the unused UCPD), SPI1 on DMA1 channels 2
    // (TX) and 1 (RX), the handshake lines' EXTI 0-2 and 10-14 (three interrupt lines on the
    // G0), USART1 on DMA1 channels 4 (TX) and 5 (RX).
    #[cfg(feature = "board-g0b1")]
    bind_interrupts!(struct Irqs {
        USB_UCPD1_2 => usb::InterruptHandler<USB>;
        DMA1_CHANNEL1 => dma::InterruptHandler<DMA1_CH1>;
        DMA1_CHANNEL2_3 => dma::InterruptHandler<DMA1_CH2>;
        EXTI0_1 => exti::InterruptHandler<interrupt::typelevel::EXTI0_1>;
        EXTI2_3 => exti::InterruptHandler<interrupt::typelevel::EXTI2_3>;
        EXTI4_15 => exti::InterruptHandler<interrupt::typelevel::EXTI4_15>;
        USART1 => uart::InterruptHandler<USART1>;
        DMA1_CH4_7_DMA2_CH1_5_DMAMUX1_OVR =>
            dma::InterruptHandler<DMA1_CH4>, dma::InterruptHandler<DMA1_CH5>;
    });

    /// DMA banks and the uploaded scene, in SRAM (`.sram`, see memory.x).
    struct Sram {
        link: [Bank; 3],
        /// The second root link's banks (SPI2).
        #[cfg(all(feature = "relay-root", feature = "board-f407"))]
        link2: [Bank; 3],
        #[cfg(all(feature = "relay-root", not(feature = "board-f407")))]
        relayed: RelayedBuffers,
        #[cfg(all(feature = "relay-root", feature = "board-f407"))]
        relayed: [rc_fw::plan::TwoLinkFrames; 2],
        /// The two `RelayedBus`es' state (their slot tables: `RELAY_SLOTS` exchanges in
        /// flight on each), here rather than in the serial task's future in the CCM, which
        /// has no room for it (written once in `main`).
        #[cfg(all(feature = "relay-root", feature = "board-f407"))]
        link_state: core::mem::MaybeUninit<Link>,
        scene: [u8; SCENE],
    }
    #[cfg(all(feature = "relay-root", feature = "board-f407"))]
    const _: () = assert!(core::mem::size_of::<Link>() <= rc_fw::plan::LINK_STATE);
    /// The root logic's link where it is not in SRAM: in the CCM (a `MasterFront`, or one
    /// link's `RelayedBus`).
    #[cfg(not(all(feature = "relay-root", feature = "board-f407")))]
    static LINK: StaticCell<Link> = StaticCell::new();

    static USB_QUEUE: UsbPipe = Pipe::new();
    /// The OTG core's receive buffer (the G0's USB peripheral has its own packet memory).
    #[cfg(not(feature = "board-g0b1"))]
    static EP_OUT: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
    static CONFIG_DESC: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
    static BOS_DESC: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
    static CONTROL: ConstStaticCell<[u8; 64]> = ConstStaticCell::new([0; 64]);
    static CDC: StaticCell<State<'static>> = StaticCell::new();
    /// The backup line: the roll call's between renders, the render's (serving nodes dead on
    /// SPI) during one.
    type Line = Mutex<CriticalSectionRawMutex, Rs485>;
    static LINE: StaticCell<Line> = StaticCell::new();
    /// The bus link's two halves share this: the front (`serial_task`, thread mode) hands
    /// transfers over, the bus task clocks them.
    static BUS: MasterShared<'static> = MasterShared::new();
    /// The second root link's (SPI2; the F407's root of relays).
    #[cfg(all(feature = "relay-root", feature = "board-f407"))]
    static BUS2: MasterShared<'static> = MasterShared::new();
    /// The bus task's executor: UART4's interrupt (unused on this board; on the G0B1 the
    /// line USART3-6 and LPUART1 share, none of them used) at a priority above thread mode,
    /// so each DMA completion resumes the clocking at once while the root logic composes
    /// the next transfer (`links_core::spi::RC_OVERLAPS`).
    static EXECUTOR_BUS: InterruptExecutor = InterruptExecutor::new();

    #[cfg(not(feature = "board-g0b1"))]
    #[interrupt]
    unsafe fn UART4() {
        // SAFETY: the interrupt executor's documented use: called from its own interrupt.
        unsafe { EXECUTOR_BUS.on_interrupt() }
    }
    #[cfg(feature = "board-g0b1")]
    #[interrupt]
    unsafe fn USART3_4_5_6_LPUART1() {
        // SAFETY: the interrupt executor's documented use: called from its own interrupt.
        unsafe { EXECUTOR_BUS.on_interrupt() }
    }
    #[cfg(not(feature = "board-g0b1"))]
    use interrupt::UART4 as BUS_IRQ;
    #[cfg(feature = "board-g0b1")]
    use interrupt::USART3_4_5_6_LPUART1 as BUS_IRQ;
    /// The bus executor's priority: above thread mode, below embassy's drivers (priority
    /// 0): 6 of the F4's and F2's 16 levels, 2 of the G0's 4.
    #[cfg(not(feature = "board-g0b1"))]
    const BUS_PRIORITY: Priority = Priority::P6;
    #[cfg(feature = "board-g0b1")]
    const BUS_PRIORITY: Priority = Priority::P2;

    /// The chip-selects and handshake lines on SPI1: every one, or the first link's half.
    #[cfg(not(all(feature = "relay-root", feature = "board-f407")))]
    type Port1 = RcPort<NODES>;
    #[cfg(all(feature = "relay-root", feature = "board-f407"))]
    type Port1 = RcPort<LINK_NODES>;

    /// Clock every transfer the root logic hands over (`links_core::spi::MasterTask`).
    #[embassy_executor::task]
    async fn bus_task(port: Port1) {
        let mut port = port;
        MasterTask::new().run(&mut port, &BUS).await
    }

    /// The same for the second root link (SPI2, its multiplexer on two select lines).
    #[cfg(all(feature = "relay-root", feature = "board-f407"))]
    #[embassy_executor::task]
    async fn bus2_task(port: RcPort<LINK_NODES, 2>) {
        let mut port = port;
        MasterTask::new().run(&mut port, &BUS2).await
    }

    #[embassy_executor::task]
    async fn usb_task(mut device: UsbDevice<'static, UsbDriver>) {
        device.run().await
    }

    /// Drain the queue into the CDC IN endpoint. Packets of at most 63 bytes are always
    /// short, so the host never waits for a zero-length packet.
    #[embassy_executor::task]
    async fn usb_tx_task(mut tx: Sender<'static, UsbDriver>) {
        let mut buf = [0u8; 63];
        loop {
            tx.wait_connection().await;
            loop {
                let n = USB_QUEUE.read(&mut buf).await;
                if tx.write_packet(&buf[..n]).await.is_err() {
                    break;
                }
            }
        }
    }

    /// The serial backup line between renders: call the roll of every node on the line
    /// (`ROLL_CALL_NODES`: all, or a 256-node tree's first 64) once a period
    /// (`links_core::backup::rc::ask_health`, one node at a time: no table of 64 healths in
    /// the task) and log who is absent and each node's health. During a render the serial
    /// task holds the line.
    #[embassy_executor::task]
    async fn backup_task(line: &'static Line) {
        loop {
            for a in 1..=ROLL_CALL_NODES {
                let mut rs485 = line.lock().await;
                let mut port = PortLine {
                    port: &mut *rs485,
                    timeout_us: REPLY_TIMEOUT_US,
                };
                match backup::rc::ask_health(&mut port, a).await {
                    Ok(Some(h)) => info!("backup line: node {}: {}", a, h),
                    Ok(None) => warn!("backup line: node {} absent", a),
                    Err(e) => warn!("backup line: {}", e),
                }
            }
            Timer::after_millis(ROLL_CALL_PERIOD_MS).await;
        }
    }

    /// The SPI link's counters after a render (as the root of relays: the relay link's;
    /// on two links, the sum).
    #[cfg(not(feature = "relay-root"))]
    fn link_counters(link: &Link) -> links_core::spi::MasterCounters {
        link.counters()
    }
    #[cfg(all(feature = "relay-root", not(feature = "board-f407")))]
    fn link_counters(link: &Link) -> links_core::spi::MasterCounters {
        link.link().counters()
    }
    #[cfg(all(feature = "relay-root", feature = "board-f407"))]
    fn link_counters(link: &Link) -> links_core::spi::MasterCounters {
        let (a, b) = link.links();
        a.link().counters().plus(&b.link().counters())
    }

    async fn queue(bytes: &[u8]) {
        USB_QUEUE.write_all(bytes).await;
    }

    /// Film frames the session has ready: each rendered from its bank (lent out of the
    /// session) while the PC's bytes go on into the session, so the next frame's upload
    /// lands in the other bank meanwhile. Upload replies wait until the queue keeps the
    /// pixel runs' room after them (`render::reply_room`).
    async fn film_frames(
        rx: &mut Receiver<'static, UsbDriver>,
        link: &mut Link,
        session: &mut Session<'static>,
        film_enc: &mut Encoder,
        last: &mut Option<FrameStreamer>,
    ) {
        while let Some((frame, n)) = session.start_next() {
            queue(session.reply(n)).await;
            let bank = bank_of(frame);
            let Some((buf, len)) = session.bank(bank).lend() else {
                warn!("film frame {}: its bank holds no scene", frame);
                continue;
            };
            info!(
                "film frame {} of {}: {} bytes",
                frame, session.film.frames, len
            );
            let (room, mut out) = (PipeQueue(&USB_QUEUE), PipeQueue(&USB_QUEUE));
            let render = render_film_frame(
                link,
                &Clock,
                &room,
                &mut out,
                &buf[..len],
                frame,
                RENDER_NODE_SET,
                film_enc,
                last,
            );
            match select(render, receive_during_render(rx, session)).await {
                Either::First(Ok(report)) => info!("frame {}: {}", frame, report),
                Either::First(Err(e)) => warn!("film frame {} failed: {}", frame, e),
                Either::Second(()) => warn!("PC disconnected during film frame {}", frame),
            }
            session.bank(bank).restore(buf);
            session.film.rendered(frame);
        }
    }

    /// The PC's bytes while a film frame renders: uploads (the next frame) are answered;
    /// anything else waits for the frame's end (the PC asks again after its time-out).
    /// Returns when the PC disconnects.
    async fn receive_during_render(
        rx: &mut Receiver<'static, UsbDriver>,
        session: &mut Session<'static>,
    ) {
        let mut pkt = [0u8; 64];
        while let Ok(n) = rx.read_packet(&mut pkt).await {
            for &b in &pkt[..n] {
                if let Step::Reply(len) = session.feed(b) {
                    let room = PipeQueue(&USB_QUEUE);
                    room.wait_room(reply_room(len)).await;
                    if !PipeQueue(&USB_QUEUE).push(session.reply(len)) {
                        warn!("upload reply dropped");
                    }
                }
            }
        }
    }

    /// The PC protocol: scene upload, render requests, readback acknowledgements, film
    /// frames (`rc_fw::session`, host-tested), acted on here.
    #[embassy_executor::task]
    async fn serial_task(
        mut rx: Receiver<'static, UsbDriver>,
        link: &'static mut Link,
        scene: &'static mut [u8],
        line: &'static Line,
    ) {
        // Two banks: still scenes and even film frames, odd film frames.
        let (even, odd) = scene.split_at_mut(FILM_BANK);
        let mut session = Session::with_banks(even, odd);
        let mut film_enc = Encoder::new();
        let mut pkt = [0u8; 64];
        let mut last: Option<FrameStreamer> = None;
        loop {
            rx.wait_connection().await;
            info!("PC connected");
            while let Ok(n) = rx.read_packet(&mut pkt).await {
                for &b in &pkt[..n] {
                    let step = session.feed(b);
                    on_step(step, link, &mut session, &mut last, line).await;
                    if session.film.current.is_none() && session.film.loading.is_some() {
                        film_frames(&mut rx, link, &mut session, &mut film_enc, &mut last).await;
                    }
                }
            }
            session.line_reset();
        }
    }

    /// Act on one step of the session (not film frames).
    async fn on_step(
        step: Step,
        link: &mut Link,
        session: &mut Session<'static>,
        last: &mut Option<FrameStreamer>,
        line: &'static Line,
    ) {
        match step {
            Step::Nothing => {}
            Step::Reply(len) => queue(session.reply(len)).await,
            Step::Acked { frame } => info!("PC has frame {}", frame),
            Step::Render { frames } => {
                let Some(image) = session.upload.image() else {
                    return;
                };
                info!("render {} frame(s) of a {}-byte scene", frames, image.len());
                // Nodes whose SPI link fails are served over the backup line.
                let mut rs485 = line.lock().await;
                let mut port = PortLine {
                    port: &mut *rs485,
                    timeout_us: REPLY_TIMEOUT_US,
                };
                let r = render_frames_with_line(
                    link,
                    &Clock,
                    &PipeQueue(&USB_QUEUE),
                    &mut PipeQueue(&USB_QUEUE),
                    image,
                    frames,
                    RENDER_NODE_SET,
                    &mut session.enc,
                    last,
                    Some((&mut port, SERVE)),
                )
                .await;
                drop(rs485);
                match r {
                    Ok(report) => info!("rendered: {} / link {}", report, link_counters(link)),
                    Err(e) => warn!("render failed: {}", e),
                }
            }
            Step::Resend { frame, start, len } => {
                // A film frame's scene is in its bank until its FrameAck; a still's in the
                // even bank.
                let image = match session.film.resend_bank(frame) {
                    Some(1) => session.odd.image(),
                    _ => session.upload.image(),
                };
                match (last.as_ref(), image) {
                    (Some(fs), Some(image)) if fs.frame() == frame => {
                        let r = resend_span(
                            fs,
                            image,
                            start,
                            len,
                            &mut session.enc,
                            &PipeQueue(&USB_QUEUE),
                            &mut PipeQueue(&USB_QUEUE),
                        )
                        .await;
                        if let Err(e) = r {
                            warn!("resend failed: {}", e);
                        }
                    }
                    _ => warn!("resend of frame {}: not the last frame", frame),
                }
            }
        }
    }

    /// Wire the board from the pin table (`rc_fw::with_pins!`, named in `rc_fw::pins` for
    /// the host tests): the USB driver and the bus port. The accelerometer's chip-select
    /// (where the table has one) is held high for good.
    macro_rules! wire {
        ($p:ident, $spi_cfg:ident;
         spi1: [$sck:ident, $miso:ident, $mosi:ident], usb: [$dm:ident, $dp:ident],
         $(accel_cs: $acc:ident,)? cs: [$($cs:ident),*],
         ready: [$($rdy:ident / $exti:ident),*], miso_sel: [$($sel:ident),*]
         $(, spi2: [$sck2:ident, $miso2:ident, $mosi2:ident], miso_sel2: [$($sel2:ident),*])?) => {{
            // The OTG core without VBUS sensing (the G0's USB device peripheral has none to
            // turn off).
            #[cfg(not(feature = "board-g0b1"))]
            let driver = {
                let mut usb_cfg = usb::Config::default();
                usb_cfg.vbus_detection = false;
                usb::Driver::new_fs($p.USB_OTG_FS, Irqs, $p.$dp, $p.$dm, EP_OUT.take(), usb_cfg)
            };
            #[cfg(feature = "board-g0b1")]
            let driver = usb::Driver::new($p.USB, Irqs, $p.$dp, $p.$dm);
            $(core::mem::forget(Output::new($p.$acc, Level::High, Speed::Low));)?
            #[cfg(not(feature = "board-g0b1"))]
            let (tx_dma, rx_dma) = ($p.DMA2_CH3, $p.DMA2_CH0);
            #[cfg(feature = "board-g0b1")]
            let (tx_dma, rx_dma) = ($p.DMA1_CH2, $p.DMA1_CH1);
            let spi = Spi::new(
                $p.SPI1, $p.$sck, $p.$mosi, $p.$miso, tx_dma, rx_dma, Irqs, $spi_cfg,
            );
            let cs = [$(Output::new($p.$cs, Level::High, Speed::VeryHigh)),*];
            let ready = [$(ExtiInput::new($p.$rdy, $p.$exti, Pull::Down, Irqs)),*];
            let miso_sel = [$(Output::new($p.$sel, Level::Low, Speed::VeryHigh)),*];
            #[cfg(not(all(feature = "relay-root", feature = "board-f407")))]
            let port = RcPort { spi, cs, ready, miso_sel };
            // The root of relays on two links: relays 0..3 on SPI1 (its multiplexer's S2
            // stays low), relays 4..7 on SPI2 (DMA1 streams 4 and 3) behind a second
            // multiplexer; the chip-selects and handshake lines split the same way.
            #[cfg(all(feature = "relay-root", feature = "board-f407"))]
            let port = {
                let [c0, c1, c2, c3, c4, c5, c6, c7] = cs;
                let [r0, r1, r2, r3, r4, r5, r6, r7] = ready;
                $(
                let spi2 = Spi::new(
                    $p.SPI2, $p.$sck2, $p.$mosi2, $p.$miso2, $p.DMA1_CH4, $p.DMA1_CH3, Irqs,
                    $spi_cfg,
                );
                let miso_sel2 = [$(Output::new($p.$sel2, Level::Low, Speed::VeryHigh)),*];
                )?
                (
                    RcPort { spi, cs: [c0, c1, c2, c3], ready: [r0, r1, r2, r3], miso_sel },
                    RcPort {
                        spi: spi2,
                        cs: [c4, c5, c6, c7],
                        ready: [r4, r5, r6, r7],
                        miso_sel: miso_sel2,
                    },
                )
            };
            (driver, port)
        }};
    }

    #[embassy_executor::main]
    async fn main(spawner: Spawner) {
        let p = links_board::init();
        info!("LINKS-1 RC up");
        // `main` runs once, so this expansion does: the only reference to the region.
        let sram: &'static mut Sram = links_board::take_sram!(Sram);

        // USB CDC (the Discovery's micro-USB, CN5) and the star: SPI1 master, one
        // chip-select and one handshake line per node, all wired from the pin table.
        let mut spi_cfg = spi::Config::default();
        spi_cfg.frequency = Hertz(rc_fw::link::SPI_HZ);
        spi_cfg.mode = spi::MODE_0;
        let (driver, port) = rc_fw::with_pins!(wire, p, spi_cfg);
        // pid.codes test VID/PID (replace before distributing boards).
        let mut config = embassy_usb::Config::new(0x1209, 0x0001);
        config.manufacturer = Some("LINKS-1");
        config.product = Some("LINKS-1 RC");
        config.serial_number = Some("RC0");
        let mut builder = Builder::new(
            driver,
            config,
            CONFIG_DESC.take(),
            BOS_DESC.take(),
            &mut [],
            CONTROL.take(),
        );
        let class = CdcAcmClass::new(&mut builder, CDC.init(State::new()), 64);
        let device = builder.build();
        let (tx, rx) = class.split();

        let [btx0, btx1, brx] = &mut sram.link;
        #[cfg(not(all(feature = "relay-root", feature = "board-f407")))]
        let front = MasterFront::new(&BUS, 0, NODES as u16, [btx0, btx1], brx);
        #[cfg(not(feature = "relay-root"))]
        let link = front;
        #[cfg(all(feature = "relay-root", not(feature = "board-f407")))]
        let link = unwrap!(RelayedBus::new(
            front,
            &mut sram.relayed,
            0,
            rc_fw::link::PER_RELAY
        ))
        .with_timeout(Clock, rc_fw::link::RELAY_TIMEOUT_US);
        // Two root links: relays 0..3 (their nodes 0..32, or under two levels 0..128) on
        // SPI1, relays 4..7 (the rest) on SPI2, one `RelayedBus` each, joined into the root
        // logic's one bus.
        #[cfg(all(feature = "relay-root", feature = "board-f407"))]
        let (link, port, port2) = {
            let (port, port2) = port;
            let per = rc_fw::link::PER_RELAY;
            let half = LINK_NODES as u16;
            let front = MasterFront::new(&BUS, 0, half, [btx0, btx1], brx);
            let [ctx0, ctx1, crx] = &mut sram.link2;
            let front2 = MasterFront::new(&BUS2, half, half, [ctx0, ctx1], crx);
            let [f0, f1] = &mut sram.relayed;
            let timeout = rc_fw::link::RELAY_TIMEOUT_US;
            let depth = rc_fw::link::RELAY_DEPTH;
            let ahead = rc_fw::link::RELAY_AHEAD_US;
            let a = unwrap!(RelayedBus::new(front, f0, 0, per));
            let a = a
                .with_slots()
                .with_timeout(Clock, timeout)
                .with_depth(depth)
                .with_ahead(ahead);
            let b = unwrap!(RelayedBus::new(front2, f1, half * per, per));
            let b = b
                .with_slots()
                .with_timeout(Clock, timeout)
                .with_depth(depth)
                .with_ahead(ahead);
            (unwrap!(TwoLinks::new(a, b)), port, port2)
        };

        // The serial backup line: its USART and driver enable (rc_fw::pins::BACKUP).
        #[cfg(feature = "board-f407")]
        let (line_tx, line_rx, line_de) = (p.PA2, p.PA3, p.PA1);
        #[cfg(feature = "board-f207")]
        let (line_tx, line_rx, line_de) = (p.PD5, p.PD6, p.PD4);
        #[cfg(feature = "board-g0b1")]
        let (line_tx, line_rx, line_de) = (p.PC4, p.PC5, p.PA1);
        #[cfg(not(feature = "board-g0b1"))]
        let (line_uart, line_tx_dma, line_rx_dma) = (p.USART2, p.DMA1_CH6, p.DMA1_CH5);
        #[cfg(feature = "board-g0b1")]
        let (line_uart, line_tx_dma, line_rx_dma) = (p.USART1, p.DMA1_CH4, p.DMA1_CH5);
        let uart = unwrap!(Uart::new(
            line_uart,
            line_rx,
            line_tx,
            line_tx_dma,
            line_rx_dma,
            Irqs,
            links_board::rs485::config(),
        ));
        let line = Rs485 {
            uart,
            de: Output::new(line_de, Level::Low, Speed::VeryHigh),
        };

        BUS_IRQ.set_priority(BUS_PRIORITY);
        let bus_spawner = EXECUTOR_BUS.start(BUS_IRQ);
        bus_spawner.spawn(unwrap!(bus_task(port)));
        #[cfg(all(feature = "relay-root", feature = "board-f407"))]
        bus_spawner.spawn(unwrap!(bus2_task(port2)));
        let line: &'static Line = LINE.init(Mutex::new(line));
        spawner.spawn(unwrap!(backup_task(line)));
        spawner.spawn(unwrap!(usb_task(device)));
        spawner.spawn(unwrap!(usb_tx_task(tx)));
        #[cfg(not(all(feature = "relay-root", feature = "board-f407")))]
        let link: &'static mut Link = LINK.init(link);
        #[cfg(all(feature = "relay-root", feature = "board-f407"))]
        let link: &'static mut Link = sram.link_state.write(link);
        spawner.spawn(unwrap!(serial_task(rx, link, &mut sram.scene, line)));
    }
}
