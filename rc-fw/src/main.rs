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
    use core::mem::MaybeUninit;
    use core::ptr::addr_of_mut;
    use defmt::{info, unwrap, warn};
    use embassy_executor::Spawner;
    use embassy_stm32::exti::{self, ExtiInput};
    use embassy_stm32::gpio::{Level, Output, Pull, Speed};
    use embassy_stm32::peripherals::{DMA2_CH0, DMA2_CH3, USB_OTG_FS};
    use embassy_stm32::spi::{self, Spi};
    use embassy_stm32::time::Hertz;
    use embassy_stm32::{bind_interrupts, dma, interrupt, usb};
    use embassy_sync::pipe::Pipe;
    use embassy_usb::class::cdc_acm::{CdcAcmClass, Receiver, Sender, State};
    use embassy_usb::{Builder, UsbDevice};
    use links_core::serial::FrameStreamer;
    use links_core::spi::{Bank, MasterLink};
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
    });

    /// DMA banks and the uploaded scene, in SRAM (`.sram`, see memory.x).
    struct Sram {
        link: [Bank; 3],
        scene: [u8; SCENE],
    }

    #[link_section = ".sram"]
    static mut SRAM: MaybeUninit<Sram> = MaybeUninit::uninit();
    static USB_QUEUE: UsbPipe = Pipe::new();
    static EP_OUT: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
    static CONFIG_DESC: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
    static BOS_DESC: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
    static CONTROL: ConstStaticCell<[u8; 64]> = ConstStaticCell::new([0; 64]);
    static CDC: StaticCell<State<'static>> = StaticCell::new();

    fn board() -> embassy_stm32::Config {
        use embassy_stm32::rcc::*;
        let mut c = embassy_stm32::Config::default();
        // 8 MHz crystal -> 168 MHz core, APB2 84 MHz (SPI1 up to 42 MHz), 48 MHz for USB.
        c.rcc.hse = Some(Hse {
            freq: Hertz(8_000_000),
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

    #[embassy_executor::main]
    async fn main(spawner: Spawner) {
        let p = embassy_stm32::init(board());
        info!("LINKS-1 RC up");
        // SAFETY: runs once; the only reference ever made to SRAM. Zeroed through the raw
        // pointer (no stack temporary), which makes every byte array valid.
        let sram: &'static mut Sram = unsafe {
            let ptr = addr_of_mut!(SRAM).cast::<Sram>();
            ptr.write_bytes(0, 1);
            &mut *ptr
        };

        // USB CDC (the Discovery's micro-USB, CN5).
        let mut usb_cfg = usb::Config::default();
        usb_cfg.vbus_detection = false;
        let driver =
            usb::Driver::new_fs(p.USB_OTG_FS, Irqs, p.PA12, p.PA11, EP_OUT.take(), usb_cfg);
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

        // The star: SPI1 master, one chip-select and one handshake line per node.
        let _accel_cs = Output::new(p.PE3, Level::High, Speed::Low);
        core::mem::forget(_accel_cs);
        let mut spi_cfg = spi::Config::default();
        spi_cfg.frequency = Hertz(21_000_000);
        spi_cfg.mode = spi::MODE_0;
        let spi = Spi::new(
            p.SPI1, p.PA5, p.PA7, p.PA6, p.DMA2_CH3, p.DMA2_CH0, Irqs, spi_cfg,
        );
        let cs = [
            Output::new(p.PE8, Level::High, Speed::VeryHigh),
            Output::new(p.PE9, Level::High, Speed::VeryHigh),
            Output::new(p.PE10, Level::High, Speed::VeryHigh),
            Output::new(p.PE11, Level::High, Speed::VeryHigh),
            Output::new(p.PE12, Level::High, Speed::VeryHigh),
            Output::new(p.PE13, Level::High, Speed::VeryHigh),
            Output::new(p.PE14, Level::High, Speed::VeryHigh),
            Output::new(p.PE15, Level::High, Speed::VeryHigh),
        ];
        let ready = [
            ExtiInput::new(p.PD0, p.EXTI0, Pull::Down, Irqs),
            ExtiInput::new(p.PD1, p.EXTI1, Pull::Down, Irqs),
            ExtiInput::new(p.PD2, p.EXTI2, Pull::Down, Irqs),
            ExtiInput::new(p.PD3, p.EXTI3, Pull::Down, Irqs),
            ExtiInput::new(p.PD6, p.EXTI6, Pull::Down, Irqs),
            ExtiInput::new(p.PD7, p.EXTI7, Pull::Down, Irqs),
            ExtiInput::new(p.PD8, p.EXTI8, Pull::Down, Irqs),
            ExtiInput::new(p.PD9, p.EXTI9, Pull::Down, Irqs),
        ];
        let [btx0, btx1, brx] = &mut sram.link;
        let miso_sel = [
            Output::new(p.PE4, Level::Low, Speed::VeryHigh),
            Output::new(p.PE5, Level::Low, Speed::VeryHigh),
            Output::new(p.PE6, Level::Low, Speed::VeryHigh),
        ];
        let port = RcPort {
            spi,
            cs,
            ready,
            miso_sel,
        };
        let link = MasterLink::new(port, 0, [btx0, btx1], brx);

        spawner.spawn(unwrap!(usb_task(device)));
        spawner.spawn(unwrap!(usb_tx_task(tx)));
        spawner.spawn(unwrap!(serial_task(rx, link, &mut sram.scene)));
    }
}
