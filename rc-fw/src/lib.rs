//! LINKS-1 root computer (RC) firmware for the STM32F407VG (feature `board-f407`, default),
//! the STM32F207ZG (`board-f207`, NUCLEO-F207ZG) or the STM32G0B1RE (`board-g0b1`,
//! NUCLEO-G0B1RE).
//!
//! The behaviour is `links_core::root::run_bus` over `links_core::spi::MasterLink` (the link
//! protocol, tested on the host against an emulated bus); the PC side speaks
//! `links_core::serial` over USB CDC, whose RC session (upload, render requests, readback,
//! throttle) is board-independent and lives there. This crate adds the board: the memory
//! plan and pin map and, for the MCU, the embassy-stm32 port ([`port`]).
#![cfg_attr(target_os = "none", no_std)]

#[cfg(target_os = "none")]
pub mod port;

// The relay role's pin table and port are the STM32F4DISCOVERY's (port E, DMA streams).
#[cfg(all(feature = "relay", feature = "board-g0b1"))]
compile_error!("the relay role (--features relay) is built for the F4 boards, not board-g0b1");
// 256 nodes are built on the F407 (its root drives the middle relays on SPI1 and SPI2).
#[cfg(all(feature = "relay-root-mid", not(feature = "board-f407")))]
compile_error!("the root of two relay levels (--features relay-root-mid) is built for the F407");

/// The link's numbers, all the board profile's ([`links_core::board::BoardProfile::F407`]):
/// the SPI clock, chip-select timing and nodes per bus the port and `main` use.
pub mod link {
    use links_core::board::{BoardProfile, LinkProfile};

    /// The board this firmware is (`links_board`'s board feature): every number below is
    /// its.
    pub const PROFILE: BoardProfile = links_board::PROFILE;
    const LINK: LinkProfile = PROFILE.link;
    /// SPI1's clock (Hz): APB2's 84 MHz / 4.
    pub const SPI_HZ: u32 = LINK.bit_rate_hz;
    /// Chip-select to first clock edge: the node's EXTI wakes its link task, which drops its
    /// handshake line and starts driving MISO (a few µs at 168 MHz; margin included).
    pub const CS_SETUP_US: u64 = LINK.cs_setup_ns as u64 / 1000;
    /// Chip-select high before the next selection: the node stops its DMA and re-arms.
    pub const CS_HOLD_US: u64 = LINK.cs_hold_ns as u64 / 1000;
    /// Nodes on the chip-selects this firmware drives (as the root of a relay tree, feature
    /// `relay-root`: its relays, each a node on one of its links).
    pub const NODES: usize = LINK.nodes_per_bus as usize;
    /// SPI buses the root logic's nodes are on: one, or as the root of a relay tree the
    /// profile's root links (the F407: SPI1 and SPI2, half the relays on each, joined by
    /// `links_core::relay::TwoLinks`).
    pub const ROOT_LINKS: usize = if cfg!(feature = "relay-root") {
        LINK.root_links as usize
    } else {
        1
    };
    /// Nodes (relays, as the root of a relay tree) on each of those buses.
    pub const LINK_NODES: usize = NODES / ROOT_LINKS;
    const _: () = assert!(ROOT_LINKS == 1 || ROOT_LINKS == 2);
    // `main` wires a second link (SPI2) on the F407's root of relays only.
    const _: () =
        assert!((ROOT_LINKS == 2) == cfg!(all(feature = "relay-root", feature = "board-f407")));
    const _: () = assert!(LINK_NODES * ROOT_LINKS == NODES);
    /// Levels of relays below the root: none, one (`relay-root`: leaf relays, each with a
    /// bus of NCs) or two (`relay-root-mid`: middle relays, each driving leaf relays).
    pub const RELAY_LEVELS: u16 = if cfg!(feature = "relay-root-mid") {
        2
    } else if cfg!(feature = "relay-root") {
        1
    } else {
        0
    };
    /// The NCs behind each of the root's relays: a leaf relay's bus holds as many as the
    /// root's; a middle relay reports as many as its report to the root has bits for
    /// (`links_core::relay::MAX_RELAY_NODES`, 4 leaf relays of 8), as the simulator's
    /// firmware tree builds it.
    pub const PER_RELAY: u16 = match RELAY_LEVELS {
        0 => 1,
        1 => LINK.nodes_per_bus,
        _ => links_core::relay::MAX_RELAY_NODES,
    };
    /// As the root of a relay tree: node exchanges in flight per relay (`RelayedBus::
    /// with_depth`): a leaf relay's 2 (`relay::DEPTH`, one on its bus and one reply down),
    /// a middle relay's 32 (`relay::MID_DEPTH`: one per node behind it, replies ahead), as
    /// the simulator's firmware relay tree keeps them.
    pub const RELAY_DEPTH: u16 = if RELAY_LEVELS == 2 {
        links_core::relay::MID_DEPTH
    } else {
        links_core::relay::DEPTH
    };
    /// As the root of relays on two links: node exchanges in flight on each link (its
    /// `RelayedBus`'s slot table): `relay::TWO_LINK_SLOTS`, or under two levels one for
    /// every node behind the link's middle relays (`relay::TWO_LEVEL_SLOTS`).
    pub const RELAY_SLOTS: usize = if RELAY_LEVELS == 2 {
        links_core::relay::TWO_LEVEL_SLOTS
    } else {
        links_core::relay::TWO_LINK_SLOTS
    };
    /// As the root of two levels: how long a reply sent ahead of a node's line may wait at
    /// its leaf relay besides the time-out (`RelayedBus::with_ahead`): the node's silence
    /// bound (it renders a run meanwhile). 0 (none sent ahead) with one level: measured no
    /// gain there (`docs/cluster.md`, "Replies held ahead").
    pub const RELAY_AHEAD_US: u64 = if RELAY_LEVELS == 2 {
        PROFILE.node_timeout_us
    } else {
        0
    };
    /// The NCs the root logic hands work to: those on its bus, or, as the root of a relay
    /// tree (`relay-root`), the nodes behind its relays.
    pub const RENDER_NODES: usize = NODES * PER_RELAY as usize;
    /// The nodes the root logic renders on, with the board's silence bound for them and,
    /// behind relays, the relay tree's job sizes (`Policy::RELAYED`, as the simulator's
    /// relay trees).
    pub const RENDER_NODE_SET: links_core::serial::render::NodeSet = {
        let on_bus = links_core::serial::render::NodeSet::on(&PROFILE, RENDER_NODES as u16);
        if cfg!(feature = "relay-root") {
            on_bus.relayed()
        } else {
            on_bus
        }
    };
    /// As the root of a relay tree: how long a node exchange through its relays may wait
    /// for the node's frame before the root gives it up (`RelayedBus::with_timeout`;
    /// `links_core::relay::root_timeout_us` of the levels below, as the simulator's
    /// firmware relay tree waits: 20 ms a level).
    pub const RELAY_TIMEOUT_US: u64 = links_core::relay::root_timeout_us(RELAY_LEVELS);
    // The timer counts whole microseconds: the profile's times must be whole too.
    const _: () =
        assert!(LINK.cs_setup_ns.is_multiple_of(1000) && LINK.cs_hold_ns.is_multiple_of(1000));
}

/// Where every large buffer lives (bytes). See `docs/hardware.md`.
pub mod plan {
    use links_core::spi::BANK;

    /// SRAM1 + SRAM2 (DMA-reachable) and CCM data RAM (CPU only): the board's.
    pub use links_board::{CCM, SRAM};
    /// Each bus's DMA banks: two TX (double-buffered: the RC composes into one while the
    /// other waits for or crosses the bus) and one RX (in SRAM), each the board profile's
    /// bank size (`links_core::spi::BANK`); one set per bus (`link::ROOT_LINKS`).
    pub const LINK_BANKS: usize = 3 * BANK * crate::link::ROOT_LINKS;
    /// One root link's `links_core::relay::RelayedBus` buffers when the root drives its
    /// relays on two (`links_core::relay::TWO_LINK_SLOTS` exchanges in flight on each,
    /// `TWO_LINK_LANDINGS` relay batches kept).
    pub type TwoLinkFrames = links_core::relay::RelayedFrames<
        { links_core::relay::TWO_LINK_SLOTS },
        { links_core::relay::TWO_LINK_LANDINGS },
    >;
    /// As the root of a relay tree (feature `relay-root`): the buffers of each link's
    /// `links_core::relay::RelayedBus` (a reply cell per node exchange in flight, four frame
    /// buffers: to compose in, for the broadcast waiting to go, for longer replies; the
    /// relay batches its node frames wait in;
    /// `links_core::relay::SLOTS` exchanges in flight on one link, `TWO_LINK_SLOTS` on each
    /// of two), in SRAM (the CCM has no room), taken from the scene's share.
    pub const RELAYED: usize = match (cfg!(feature = "relay-root"), crate::link::ROOT_LINKS) {
        (false, _) => 0,
        (true, 1) => core::mem::size_of::<links_core::relay::RelayedBuffers>(),
        (true, links) => links * core::mem::size_of::<TwoLinkFrames>(),
    };
    /// As the root of relays on two links (the F407's `relay-root`): room for the two
    /// `RelayedBus`es' state (their slot tables), which `main` keeps in SRAM (a compile-time
    /// assertion there checks it fits); the CCM has no room for it. Under two levels each
    /// link keeps an exchange for every node behind it (`link::RELAY_SLOTS`, 24 bytes a
    /// slot): 6,616 bytes in all.
    pub const LINK_STATE: usize = match (crate::link::ROOT_LINKS, crate::link::RELAY_LEVELS) {
        (2, 2) => 7 * 1024,
        (2, _) => 2048,
        _ => 0,
    };
    /// The uploaded SceneImage (in SRAM; the USB FIFO is read by the CPU, the nodes get it
    /// through the TX bank): what the DMA banks (and the relay buffers and state) leave, in
    /// whole KB.
    pub const SCENE: usize = (SRAM - LINK_BANKS - RELAYED - LINK_STATE) / 1024 * 1024;
    /// The first of a film's two scene banks, which split [`SCENE`]: frame k is uploaded
    /// into one while frame k - 1 renders from the other (`links_core::serial::film`); a
    /// still scene uses the first. Half of [`SCENE`], or a node's larger scene bank if that
    /// is more, so every still a node can take fits the RC: on the F407 both halves (62,976
    /// bytes) exceed a node's bank; on the F207 the first is the node's 40 KB bank and the
    /// second what is left, which bounds a film's frames there (an upload names the bank
    /// it does not fit). No RAM is added: the region is shared out.
    pub const FILM_BANK: usize = {
        let half = SCENE / 2;
        let node = crate::link::PROFILE.node.bank(0);
        if node > half {
            node
        } else {
            half
        }
    };
    /// Bytes of serial frames queued for USB (in CCM). The root of a relay tree keeps
    /// 5.5 KB (still above both bounds below, the throttle's 5,586): its serial task holds
    /// `RelayedBus`, whose state for several node exchanges in flight took the CCM past its
    /// statics budget (`scripts/fw-size f407-relay-root`: 50,208 bytes against 49,152 at
    /// 8 KB; 6 KB held one root link, two links' state needed the last half KB).
    pub const USB_QUEUE: usize = if cfg!(feature = "relay-root") {
        11 * 512
    } else {
        8 * 1024
    };

    const _: () = assert!(LINK_BANKS + RELAYED + LINK_STATE + SCENE <= SRAM);
    const _: () = assert!(SCENE <= links_core::wire::MAX_SCENE);
    // Every SceneImage a node's bank holds fits one film bank of the RC.
    const _: () = assert!(FILM_BANK >= crate::link::PROFILE.node.bank(0));
    const _: () = assert!(FILM_BANK <= SCENE);
    const _: () = assert!(USB_QUEUE >= 4 * links_core::serial::MAX_TO_PC);
    // The throttle holds two exchanges' runs back (one may be in flight, double buffering)
    // plus a frame header.
    const _: () =
        assert!(USB_QUEUE >= 2 * crate::readback::RUN_RESERVE + links_core::serial::MAX_TO_PC);
}

/// The RC board's pin table (STM32F4DISCOVERY; see `docs/hardware.md`), written once: calls
/// `$m!(args; table)` with every pin as an identifier. [`pins`] turns it into names for the
/// host tests, the firmware's `main` into the peripherals it wires, so the two cannot drift.
#[cfg(not(any(feature = "board-f207", feature = "board-g0b1")))]
#[macro_export]
macro_rules! with_pins {
    ($m:ident $(, $arg:ident)*) => {
        $m! {$($arg),*;
            spi1: [PA5, PA6, PA7],
            usb: [PA11, PA12],
            accel_cs: PE3,
            cs: [PE8, PE9, PE10, PE11, PE12, PE13, PE14, PE15],
            ready: [PD0 / EXTI0, PD1 / EXTI1, PD2 / EXTI2, PD3 / EXTI3,
                    PD6 / EXTI6, PD7 / EXTI7, PD8 / EXTI8, PD9 / EXTI9],
            miso_sel: [PE4, PE5, PE6],
            spi2: [PB13, PB14, PB15],
            miso_sel2: [PD10, PD11]
        }
    };
}

/// The RC board's pin table on the NUCLEO-F207ZG (see `docs/hardware.md`): the F407's but
/// for the handshake lines the ST-LINK's virtual COM port (PD8/PD9) and PD4-PD6 (the backup
/// line) take: PD7 and PD10-PD12 instead. PE3 (the Discovery's accelerometer select) is a
/// free pin here, held high all the same. PA7 (MOSI) is also the Ethernet PHY's
/// RMII_CRS_DV: remove JP6.
#[cfg(feature = "board-f207")]
#[macro_export]
macro_rules! with_pins {
    ($m:ident $(, $arg:ident)*) => {
        $m! {$($arg),*;
            spi1: [PA5, PA6, PA7],
            usb: [PA11, PA12],
            accel_cs: PE3,
            cs: [PE8, PE9, PE10, PE11, PE12, PE13, PE14, PE15],
            ready: [PD0 / EXTI0, PD1 / EXTI1, PD2 / EXTI2, PD3 / EXTI3,
                    PD7 / EXTI7, PD10 / EXTI10, PD11 / EXTI11, PD12 / EXTI12],
            miso_sel: [PE4, PE5, PE6]
        }
    };
}

/// The RC board's pin table on the NUCLEO-G0B1RE (UM2324; see `docs/hardware.md`): SPI1
/// on the NC board's PB3/PB4/PB5 (D3/D5/D4, away from LD4 on PA5), USB on PA11/PA12 (morpho
/// CN10-14/CN10-12, to a USB connector of its own: the board has only the ST-LINK's), the
/// chip-selects on port C (morpho), the handshake lines on port B, each on its own EXTI
/// line (0-2, 10-14), the MISO multiplexer's selects on D7/D8/D2 (PA8/PA9/PA10). No
/// accelerometer shares SPI1 here.
#[cfg(feature = "board-g0b1")]
#[macro_export]
macro_rules! with_pins {
    ($m:ident $(, $arg:ident)*) => {
        $m! {$($arg),*;
            spi1: [PB3, PB4, PB5],
            usb: [PA11, PA12],
            cs: [PC0, PC1, PC2, PC3, PC6, PC7, PC8, PC9],
            ready: [PB0 / EXTI0, PB1 / EXTI1, PB2 / EXTI2, PB10 / EXTI10,
                    PB11 / EXTI11, PB12 / EXTI12, PB13 / EXTI13, PB14 / EXTI14],
            miso_sel: [PA8, PA9, PA10]
        }
    };
}

/// The pin table's names (see [`with_pins!`]).
macro_rules! pin_names {
    (; spi1: [$($spi:ident),*], usb: [$($usb:ident),*], $(accel_cs: $acc:ident,)?
       cs: [$($cs:ident),*], ready: [$($rdy:ident / $exti:ident),*],
       miso_sel: [$($sel:ident),*]
       $(, spi2: [$($spi2:ident),*], miso_sel2: [$($sel2:ident),*])?) => {
        /// SPI2 (master): SCK, MISO, MOSI: the second root link of a root of relays
        /// (`relay-root` on the F407: relays 4..7); empty on boards whose root drives one.
        pub const SPI2: &[&str] = &[$($(stringify!($spi2)),*)?];
        /// Select lines S0, S1 of the second link's 74LVC251 (its S2 tied low: 4 relays).
        pub const MISO_SEL2: &[&str] = &[$($(stringify!($sel2)),*)?];
        /// SPI1 (master): SCK, MISO, MOSI.
        pub const SPI1: [&str; 3] = [$(stringify!($spi)),*];
        /// Chip-select outputs, node 0..7 (active low).
        pub const CS: [&str; NODES] = [$(stringify!($cs)),*];
        /// Handshake inputs with EXTI (pull-down: an absent node reads "not ready").
        pub const READY: [&str; NODES] = [$(stringify!($rdy)),*];
        /// The EXTI line of each handshake input (must match its pin number).
        pub const READY_EXTI: [&str; NODES] = [$(stringify!($exti)),*];
        /// Select lines S0..S2 of the 8:1 MISO multiplexer (74LVC251: node i's MISO on input i).
        pub const MISO_SEL: [&str; 3] = [$(stringify!($sel)),*];
        /// USB OTG FS (the Discovery's micro-USB CN5): D-, D+.
        pub const USB: [&str; 2] = [$(stringify!($usb)),*];
        /// The Discovery's accelerometer shares SPI1: its chip-select is held high (the
        /// F4 and F2 tables; none on the G0B1's).
        pub const ACCEL_CS: Option<&str> = optional_pin!($($acc)?);
    };
}

/// A pin the table may leave out, by name.
macro_rules! optional_pin {
    () => {
        None
    };
    ($pin:ident) => {
        Some(stringify!($pin))
    };
}

/// Pins of the RC board (STM32F4DISCOVERY), from the one table [`with_pins!`] that `main`
/// wires. See `docs/hardware.md`.
pub mod pins {
    /// Nodes on the one bus this firmware drives (one chip-select and one handshake line
    /// each; EXTI lines must differ, so at most 16 per RC without a decoder): the board
    /// profile's ([`crate::link::NODES`]); the pin table must list that many.
    pub use crate::link::NODES;
    crate::with_pins!(pin_names);
    /// The serial backup line (RS-485, `links_core::backup`): USART2 TX, RX, and the
    /// transceiver's driver enable (also its /RE). Free of every pin above and of the
    /// Discovery's on-board parts.
    #[cfg(not(any(feature = "board-f207", feature = "board-g0b1")))]
    pub const BACKUP: [&str; 3] = ["PA2", "PA3", "PA1"];
    /// The serial backup line: USART2 on PD5 (TX), PD6 (RX), driver enable PD4 (the
    /// Nucleo's PA1/PA2 are the Ethernet PHY's).
    #[cfg(feature = "board-f207")]
    pub const BACKUP: [&str; 3] = ["PD5", "PD6", "PD4"];
    /// The serial backup line: USART1 on PC4 (TX, D1), PC5 (RX, D0), driver enable PA1
    /// (A1): the NC board's (USART2's PA2/PA3 are the ST-LINK's virtual COM port).
    #[cfg(feature = "board-g0b1")]
    pub const BACKUP: [&str; 3] = ["PC4", "PC5", "PA1"];
}

/// The relay role's pin table (`--features relay`; `docs/hardware.md`, "Reaching 64 and
/// 256 nodes"), written once like [`with_pins!`]: the parent's link on SPI1 as a slave (the
/// NC board's pins), the relay's own bus on SPI2 as master (the RC's chip-selects and MISO
/// multiplexer; the first handshake line moves from PD0 to PD10 because EXTI0 is the parent
/// link's chip-select sense).
#[macro_export]
macro_rules! with_relay_pins {
    ($m:ident $(, $arg:ident)*) => {
        $m! {$($arg),*;
            parent: [PA5, PA6, PA7, PA4], cs_sense: PB0 / EXTI0, ready_out: PB1,
            spi2: [PB13, PB14, PB15],
            accel_cs: PE3,
            cs: [PE8, PE9, PE10, PE11, PE12, PE13, PE14, PE15],
            ready: [PD10 / EXTI10, PD1 / EXTI1, PD2 / EXTI2, PD3 / EXTI3,
                    PD6 / EXTI6, PD7 / EXTI7, PD8 / EXTI8, PD9 / EXTI9],
            miso_sel: [PE4, PE5, PE6]
        }
    };
}

/// The relay table's names (see [`with_relay_pins!`]).
macro_rules! relay_pin_names {
    (; parent: [$($par:ident),*], cs_sense: $sense:ident / $sexti:ident, ready_out: $rdy_out:ident,
       spi2: [$($spi:ident),*], accel_cs: $acc:ident, cs: [$($cs:ident),*],
       ready: [$($rdy:ident / $exti:ident),*], miso_sel: [$($sel:ident),*]) => {
        /// SPI1 (slave, towards the parent): SCK, MISO, MOSI, NSS.
        pub const PARENT: [&str; 4] = [$(stringify!($par)),*];
        /// The parent's chip-select, sensed, and its EXTI line.
        pub const CS_SENSE: [&str; 2] = [stringify!($sense), stringify!($sexti)];
        /// Handshake output to the parent.
        pub const READY_OUT: &str = stringify!($rdy_out);
        /// SPI2 (master of the relay's bus): SCK, MISO, MOSI.
        pub const SPI2: [&str; 3] = [$(stringify!($spi)),*];
        /// Chip-select outputs of the relay's nodes.
        pub const CS: [&str; NODES] = [$(stringify!($cs)),*];
        /// Handshake inputs of the relay's nodes.
        pub const READY: [&str; NODES] = [$(stringify!($rdy)),*];
        /// Their EXTI lines.
        pub const READY_EXTI: [&str; NODES] = [$(stringify!($exti)),*];
        /// MISO multiplexer selects.
        pub const MISO_SEL: [&str; 3] = [$(stringify!($sel)),*];
        /// The accelerometer's chip-select (shares SPI1's pins), held high.
        pub const ACCEL_CS: &str = stringify!($acc);
    };
}

/// Pins of a relay board (`--features relay`), from [`with_relay_pins!`].
pub mod relay_pins {
    pub use crate::link::NODES;
    crate::with_relay_pins!(relay_pin_names);
}

/// The backup line's numbers, the board profile's: its bit rate, the reply timeout of a
/// roll call, and how often the RC calls the roll.
pub mod backup_line {
    use links_core::board::LineProfile;

    const LINE: LineProfile = crate::link::PROFILE.backup;
    /// USART2's bit rate.
    pub const BIT_RATE: u32 = LINE.bit_rate_hz;
    /// How long a node has to answer (µs).
    pub const REPLY_TIMEOUT_US: u32 = LINE.reply_timeout_us;
    /// The RC calls the roll this often (ms).
    pub const ROLL_CALL_PERIOD_MS: u64 = 1000;
    /// The nodes the roll call asks: line addresses 1..=this. A node's address straps
    /// have 6 bits (`links_core::backup::MAX_ADDR` = 64), so the line reaches the first 64
    /// of a 256-node tree (the rest are reached by SPI only); `SERVE` clamps the same way.
    pub const ROLL_CALL_NODES: u8 = {
        let max = links_core::backup::MAX_ADDR as usize;
        let nodes = crate::link::RENDER_NODES;
        (if nodes < max { nodes } else { max }) as u8
    };
    /// During a render: nodes on the line, how often the RC calls one that failed on SPI,
    /// how long the line rests when no served node has anything to do
    /// (`links_core::backup::serve_root`).
    pub const SERVE: links_core::backup::ServeConfig = links_core::backup::ServeConfig {
        nodes: crate::link::RENDER_NODES as u16,
        call_gap_us: 100_000,
        idle_us: 1_000,
    };
}

// The PC conversation, render requests, readback and throttle are board-independent: they
// live in `links_core::serial` (host-tested there and driven by the host's simulated RC).
pub use links_core::serial::{readback, render, session, throttle};

#[cfg(test)]
mod tests {
    use links_core::board::BoardProfile;

    /// The root of a relay tree (`--features relay-root`, run by `scripts/test-all`) reaches
    /// the nodes behind its relays and pays for `RelayedBus`'s buffers out of the scene's
    /// SRAM; the plain root drives its own bus's nodes and keeps all of it.
    #[test]
    fn the_root_of_relays_reaches_its_nodes_and_its_buffers_come_from_the_scene() {
        use super::link::{NODES, PROFILE, RENDER_NODES};
        use super::plan::{FILM_BANK, RELAYED, SCENE};
        let per_bus = PROFILE.link.nodes_per_bus as usize;
        // A reply cell per exchange in flight, four frame buffers, the relay batches kept.
        use links_core::relay::{LANDINGS, REPLY_CELL, SLOTS, TWO_LINK_LANDINGS, TWO_LINK_SLOTS};
        use links_core::wire::MAX_MESSAGE;
        let relayed = core::mem::size_of::<links_core::relay::RelayedBuffers>();
        assert_eq!(relayed, SLOTS * REPLY_CELL + (4 + LANDINGS) * MAX_MESSAGE);
        assert_eq!(relayed, 13_632);
        if cfg!(feature = "relay-root") {
            let links = PROFILE.link.root_links as usize;
            let two = core::mem::size_of::<super::plan::TwoLinkFrames>();
            assert_eq!(
                two,
                TWO_LINK_SLOTS * REPLY_CELL + (4 + TWO_LINK_LANDINGS) * MAX_MESSAGE
            );
            assert_eq!(two, 16_232);
            let expected = if links == 2 { 2 * two } else { relayed };
            // A leaf relay brings its bus's nodes; a middle relay the 32 its report holds
            // (4 leaf relays of 8), as the simulator's firmware tree builds 256 nodes.
            let (levels, per_relay, timeout_us) = if cfg!(feature = "relay-root-mid") {
                (2, 32, 40_000)
            } else {
                (1, per_bus, 20_000)
            };
            assert_eq!((RENDER_NODES, RELAYED), (NODES * per_relay, expected));
            assert_eq!(
                (super::link::RELAY_LEVELS, super::link::RELAY_TIMEOUT_US),
                (levels, timeout_us)
            );
            // The simulator's relay trees divide the frame the same way.
            assert_eq!(
                super::link::RENDER_NODE_SET.policy,
                links_core::sched::Policy::RELAYED
            );
            assert_eq!(
                super::plan::LINK_BANKS,
                3 * links * PROFILE.dma_bank_bytes()
            );
            if cfg!(feature = "board-f407") {
                // Two root links (SPI1, SPI2): 128 KB - 2 x 3 DMA banks - 2 x 16,232 B (32
                // reply cells on each) - the links' state (2 KB; under two levels 7 KB, an
                // exchange in flight for every node: replies go ahead), in whole KB; a
                // film's second bank is what the first (a node's 61,440-byte bank) leaves:
                // 24,576 B (19,456 under two levels; 58,368 with one exchange in flight
                // a link). photo1-orbit's frames are 18 KB.
                assert_eq!(links, 2);
                let (nodes, state, scene) = if levels == 2 {
                    (256, 7 * 1024, 80_896)
                } else {
                    (64, 2048, 86_016)
                };
                assert_eq!(super::plan::LINK_STATE, state);
                assert_eq!((RENDER_NODES, SCENE, FILM_BANK), (nodes, scene, 61_440));
                // The backup line's 6-bit addresses reach a 256-node tree's first 64.
                assert_eq!(super::backup_line::ROLL_CALL_NODES, 64);
            }
            if cfg!(feature = "board-g0b1") {
                // 80 KB - 3 DMA banks - 13,632 B = 63,524 -> 62 KB; the first film bank is a
                // node's 40 KB bank, as without the relays (the second: 22 KB; 6 KB while
                // each exchange in flight kept a frame buffer).
                assert_eq!((RENDER_NODES, SCENE, FILM_BANK), (64, 63_488, 40_960));
            }
        } else {
            assert_eq!((RENDER_NODES, RELAYED), (NODES, 0));
            assert_eq!(super::backup_line::ROLL_CALL_NODES as usize, NODES);
            assert_eq!(
                super::link::RENDER_NODE_SET.policy,
                links_core::sched::Policy::DECREASING
            );
        }
        // LINK_BANKS + RELAYED + SCENE <= SRAM and FILM_BANK <= SCENE: the plan's
        // compile-time assertions.
    }

    /// Every link number of this firmware is its board profile's (the F207's with
    /// `--no-default-features --features board-f207`, the G0B1's with `board-g0b1`).
    #[test]
    fn the_firmware_constants_are_the_board_profile() {
        let p = if cfg!(feature = "board-f207") {
            BoardProfile::F207
        } else if cfg!(feature = "board-g0b1") {
            BoardProfile::G0B1
        } else {
            BoardProfile::F407
        };
        assert_eq!(super::link::PROFILE, p);
        assert_eq!(super::link::RENDER_NODE_SET.timeout_us, p.node_timeout_us);
        assert_eq!(super::link::SPI_HZ, p.link.bit_rate_hz);
        let (hz, setup, hold) = if cfg!(feature = "board-f207") {
            (15_000_000, 12, 21)
        } else if cfg!(feature = "board-g0b1") {
            (16_000_000, 21, 40)
        } else {
            (21_000_000, 8, 15)
        };
        assert_eq!(super::link::SPI_HZ, hz);
        assert_eq!(super::link::CS_SETUP_US * 1000, p.link.cs_setup_ns as u64);
        assert_eq!(super::link::CS_HOLD_US * 1000, p.link.cs_hold_ns as u64);
        assert_eq!(
            (super::link::CS_SETUP_US, super::link::CS_HOLD_US),
            (setup, hold)
        );
        assert_eq!(super::pins::NODES, p.link.nodes_per_bus as usize);
        assert_eq!(super::backup_line::BIT_RATE, p.backup.bit_rate_hz);
        assert_eq!(
            super::backup_line::REPLY_TIMEOUT_US,
            p.backup.reply_timeout_us
        );
        // The backup line's pins are none of the star's.
        for b in super::pins::BACKUP {
            assert!(
                !super::pins::CS.contains(&b) && !super::pins::READY.contains(&b),
                "{b}"
            );
        }
        assert_eq!(super::pins::CS.len(), super::pins::NODES);
        assert_eq!(
            super::plan::LINK_BANKS,
            3 * super::link::ROOT_LINKS * p.dma_bank_bytes()
        );
        assert_eq!(links_core::spi::HEADER, p.link.header_bytes as usize);
        assert_eq!(links_core::spi::TRAILER, p.link.trailer_bytes as usize);
        assert_eq!(links_core::spi::RC_OVERLAPS, p.link.rc_overlaps);
        assert_eq!(links_board::CORE_CLOCK_HZ, p.core_clock_hz);
    }

    /// The G0B1's RC plan: the 80 KB SRAM region less three DMA banks, in whole KB, for the
    /// scene; a film's first bank is a node's 40 KB bank (more than half), the second what
    /// is left (`cargo test -p rc-fw --no-default-features --features board-g0b1`).
    #[cfg(all(feature = "board-g0b1", not(feature = "relay-root")))]
    #[test]
    fn the_g0b1_plan_and_pins() {
        use super::plan::{FILM_BANK, LINK_BANKS, SCENE, SRAM};
        // (81,920 - 3 x 1,588) / 1,024 = 75.3 -> 75 KB.
        assert_eq!((SRAM, LINK_BANKS, SCENE), (81_920, 4_764, 76_800));
        assert_eq!((FILM_BANK, SCENE - FILM_BANK), (40_960, 35_840));
        assert_eq!(super::pins::ACCEL_CS, None);
        assert_eq!(super::pins::USB, ["PA11", "PA12"]);
        assert_eq!(super::pins::SPI1, ["PB3", "PB4", "PB5"]);
    }

    /// The relay's table: no pin twice, every EXTI line once (the parent's chip-select sense
    /// included), the parent link on the NC board's pins.
    #[test]
    fn relay_pins_are_distinct_and_exti_lines_differ() {
        use super::relay_pins as r;
        let mut all: Vec<&str> = r::CS.to_vec();
        all.extend(r::READY);
        all.extend(r::PARENT);
        all.extend(r::SPI2);
        all.extend(r::MISO_SEL);
        all.extend([r::CS_SENSE[0], r::READY_OUT, r::ACCEL_CS]);
        let n = all.len();
        all.sort();
        all.dedup();
        assert_eq!(all.len(), n, "no pin used twice");
        let mut lines: Vec<&str> = r::READY_EXTI.to_vec();
        lines.push(r::CS_SENSE[1]);
        lines.sort();
        lines.dedup();
        assert_eq!(lines.len(), r::NODES + 1, "one EXTI line each");
        for (pin, exti) in r::READY
            .iter()
            .zip(r::READY_EXTI)
            .chain([(&r::CS_SENSE[0], r::CS_SENSE[1])])
        {
            let line = pin.trim_start_matches(|c: char| c.is_ascii_alphabetic());
            assert_eq!(exti, format!("EXTI{line}"), "{pin} is on its own EXTI line");
        }
        // The parent's end is the NC's (nc-fw's port drives it).
        assert_eq!(r::PARENT, ["PA5", "PA6", "PA7", "PA4"]);
        assert_eq!((r::CS_SENSE[0], r::READY_OUT), ("PB0", "PB1"));
    }

    #[test]
    fn pins_are_distinct_and_exti_lines_differ() {
        let mut all: Vec<&str> = super::pins::CS.to_vec();
        all.extend(super::pins::READY);
        all.extend(super::pins::SPI1);
        all.extend(super::pins::USB);
        all.extend(super::pins::MISO_SEL);
        all.extend(super::pins::ACCEL_CS);
        all.extend(super::pins::BACKUP);
        all.extend(super::pins::SPI2);
        all.extend(super::pins::MISO_SEL2);
        // A second root link (the F407's) has its SPI and the selects for its relays.
        if super::link::PROFILE.link.root_links == 2 {
            assert_eq!(super::pins::SPI2, ["PB13", "PB14", "PB15"]);
            let relays = super::link::PROFILE.link.nodes_per_bus as usize / 2;
            assert!(1 << super::pins::MISO_SEL2.len() >= relays);
        }
        let n = all.len();
        all.sort();
        all.dedup();
        assert_eq!(all.len(), n, "no pin used twice");
        let mut lines: Vec<&str> = super::pins::READY
            .iter()
            .map(|p| p.trim_start_matches(|c: char| c.is_ascii_alphabetic()))
            .collect();
        lines.sort();
        lines.dedup();
        assert_eq!(lines.len(), super::pins::NODES, "one EXTI line per node");
        for (pin, exti) in super::pins::READY.iter().zip(super::pins::READY_EXTI) {
            let line = pin.trim_start_matches(|c: char| c.is_ascii_alphabetic());
            assert_eq!(exti, format!("EXTI{line}"), "{pin} is on its own EXTI line");
        }
    }
}
