//! RC bring-up: clocks, USB CDC (scene upload, frame readback: `links_core::serial`), the SPI
//! star (chip-selects, handshake EXTI) and `links_core::root::run_bus` over it.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "rc-fw is firmware for the STM32F407VG: \
         cargo run --release --target thumbv7em-none-eabihf -p rc-fw"
    );
    std::process::exit(2);
}

#[cfg(target_os = "none")]
mod fw {
    use defmt::{info, unwrap, warn};
    use embassy_executor::Spawner;
    use embassy_stm32::exti::{self, ExtiInput};
    use embassy_stm32::gpio::{Level, Output, Pull, Speed};
    use embassy_stm32::peripherals::{DMA1_CH5, DMA1_CH6, DMA2_CH0, DMA2_CH3, USART2, USB_OTG_FS};
    use embassy_stm32::spi::{self, Spi};
    use embassy_stm32::time::Hertz;
    use embassy_stm32::usart::{self as uart, Uart};
    use embassy_stm32::{bind_interrupts, dma, interrupt, usb};
    use embassy_sync::pipe::Pipe;
    use embassy_time::Timer;
    use embassy_usb::class::cdc_acm::{CdcAcmClass, Receiver, Sender, State};
    use embassy_usb::{Builder, UsbDevice};
    use links_board::rs485::Rs485;
    use links_core::backup;
    use links_core::serial::FrameStreamer;
    use links_core::spi::{Bank, MasterLink};
    use rc_fw::backup_line::{REPLY_TIMEOUT_US, ROLL_CALL_PERIOD_MS};
    use rc_fw::pins::NODES;
    use rc_fw::plan::SCENE;
    use rc_fw::port::{Clock, PipeQueue, RcPort, UsbPipe};
    use rc_fw::render::{render_frames, resend_span};
    use rc_fw::session::{Session, Step};
    use static_cell::{ConstStaticCell, StaticCell};
    use {defmt_rtt as _, panic_probe as _};

    type UsbDriver = usb::Driver<'static, USB_OTG_FS>;
    type Link = MasterLink<'static, RcPort<NODES>>;

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
    });

    /// DMA banks and the uploaded scene, in SRAM (`.sram`, see memory.x).
    struct Sram {
        link: [Bank; 3],
        scene: [u8; SCENE],
    }

    static USB_QUEUE: UsbPipe = Pipe::new();
    static EP_OUT: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
    static CONFIG_DESC: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
    static BOS_DESC: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
    static CONTROL: ConstStaticCell<[u8; 64]> = ConstStaticCell::new([0; 64]);
    static CDC: StaticCell<State<'static>> = StaticCell::new();

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

    /// The serial backup line: call the roll of every node (`links_core::backup`) once a
    /// period and log who is absent and each node's health.
    #[embassy_executor::task]
    async fn backup_task(mut line: Rs485) {
        loop {
            match backup::call_roll(&mut line, NODES as u8, REPLY_TIMEOUT_US).await {
                Ok(rc) => {
                    for a in rc.absent() {
                        warn!("backup line: node {} absent", a);
                    }
                    for a in 1..=NODES as u8 {
                        if let Some(h) = rc.health(a) {
                            info!("backup line: node {}: {}", a, h);
                        }
                    }
                }
                Err(e) => warn!("backup line: {}", e),
            }
            Timer::after_millis(ROLL_CALL_PERIOD_MS).await;
        }
    }

    async fn queue(bytes: &[u8]) {
        USB_QUEUE.write_all(bytes).await;
    }

    /// The PC protocol: scene upload, render requests, readback acknowledgements
    /// (`rc_fw::session`, host-tested), acted on here.
    #[embassy_executor::task]
    async fn serial_task(
        mut rx: Receiver<'static, UsbDriver>,
        mut link: Link,
        scene: &'static mut [u8],
    ) {
        let mut session = Session::new(scene);
        let mut pkt = [0u8; 64];
        let mut last: Option<FrameStreamer> = None;
        loop {
            rx.wait_connection().await;
            info!("PC connected");
            while let Ok(n) = rx.read_packet(&mut pkt).await {
                for &b in &pkt[..n] {
                    match session.feed(b) {
                        Step::Nothing => {}
                        Step::Reply(len) => queue(session.reply(len)).await,
                        Step::Acked { frame } => info!("PC has frame {}", frame),
                        Step::Render { frames } => {
                            let Some(image) = session.upload.image() else {
                                continue;
                            };
                            info!("render {} frame(s) of a {}-byte scene", frames, image.len());
                            let r = render_frames(
                                &mut link,
                                &Clock,
                                &PipeQueue(&USB_QUEUE),
                                &mut PipeQueue(&USB_QUEUE),
                                image,
                                frames,
                                NODES as u16,
                                &mut session.enc,
                                &mut last,
                            )
                            .await;
                            match r {
                                Ok(report) => {
                                    info!("rendered: {} / link {}", report, link.counters)
                                }
                                Err(e) => warn!("render failed: {}", e),
                            }
                        }
                        Step::Resend { frame, start, len } => {
                            match (last.as_ref(), session.upload.image()) {
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
            }
            session.line_reset();
        }
    }

    /// Wire the board from the pin table (`rc_fw::with_pins!`, named in `rc_fw::pins` for
    /// the host tests): the USB driver and the bus port. The accelerometer's chip-select is
    /// held high for good.
    macro_rules! wire {
        ($p:ident, $usb_cfg:ident, $spi_cfg:ident;
         spi1: [$sck:ident, $miso:ident, $mosi:ident], usb: [$dm:ident, $dp:ident],
         accel_cs: $acc:ident, cs: [$($cs:ident),*], ready: [$($rdy:ident / $exti:ident),*],
         miso_sel: [$($sel:ident),*]) => {{
            let driver =
                usb::Driver::new_fs($p.USB_OTG_FS, Irqs, $p.$dp, $p.$dm, EP_OUT.take(), $usb_cfg);
            let accel_cs = Output::new($p.$acc, Level::High, Speed::Low);
            core::mem::forget(accel_cs);
            let spi = Spi::new(
                $p.SPI1, $p.$sck, $p.$mosi, $p.$miso, $p.DMA2_CH3, $p.DMA2_CH0, Irqs, $spi_cfg,
            );
            let cs = [$(Output::new($p.$cs, Level::High, Speed::VeryHigh)),*];
            let ready = [$(ExtiInput::new($p.$rdy, $p.$exti, Pull::Down, Irqs)),*];
            let miso_sel = [$(Output::new($p.$sel, Level::Low, Speed::VeryHigh)),*];
            let port = RcPort { spi, cs, ready, miso_sel };
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
        let mut usb_cfg = usb::Config::default();
        usb_cfg.vbus_detection = false;
        let mut spi_cfg = spi::Config::default();
        spi_cfg.frequency = Hertz(rc_fw::link::SPI_HZ);
        spi_cfg.mode = spi::MODE_0;
        let (driver, port) = rc_fw::with_pins!(wire, p, usb_cfg, spi_cfg);
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
        let link = MasterLink::new(port, 0, [btx0, btx1], brx);

        // The serial backup line: USART2 and its driver enable (rc_fw::pins::BACKUP).
        #[cfg(not(feature = "board-f207"))]
        let (line_tx, line_rx, line_de) = (p.PA2, p.PA3, p.PA1);
        #[cfg(feature = "board-f207")]
        let (line_tx, line_rx, line_de) = (p.PD5, p.PD6, p.PD4);
        let uart = unwrap!(Uart::new(
            p.USART2,
            line_rx,
            line_tx,
            p.DMA1_CH6,
            p.DMA1_CH5,
            Irqs,
            links_board::rs485::config(),
        ));
        let line = Rs485 {
            uart,
            de: Output::new(line_de, Level::Low, Speed::VeryHigh),
        };

        spawner.spawn(unwrap!(backup_task(line)));
        spawner.spawn(unwrap!(usb_task(device)));
        spawner.spawn(unwrap!(usb_tx_task(tx)));
        spawner.spawn(unwrap!(serial_task(rx, link, &mut sram.scene)));
    }
}
