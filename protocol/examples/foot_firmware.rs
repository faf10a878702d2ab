//! A foot board's firmware, written as it would run on the microcontroller, with two host
//! drivers standing in for its CAN peripheral.
//!
//! The firmware part (`firmware` below) uses only the `no_std` crate `presrs-wire`:
//! [`Foot`] over an [`embedded_can::blocking::Can`] driver, a stack image buffer, a µs clock. On
//! a board, `Board` would read the switch's GPIO and scan the tactile array; here it is a
//! synthetic foot that hops (240 ms stance, 200 ms flight) and presses its whole sole.
//!
//! ```sh
//! # a candump log the node replays (no CAN needed):
//! cargo run -p presrs-protocol --example foot_firmware -- --log foot.log --steps 20
//! presrs node --replay foot.log --model model.json --json
//! # live, on a virtual CAN FD bus (sudo ./vcan-setup.sh vcan0), in real time:
//! cargo run -p presrs-protocol --example foot_firmware -- --iface vcan0 --steps 20
//! ```

use std::io::Write;

use presrs_protocol::candump;
use presrs_protocol::{CanFrame, Stamped};

/// What would be the firmware's crate: no heap, no std, one loop.
mod firmware {
    use wire::foot::{Foot, FootError};
    use wire::ids::IdConfig;
    use wire::tactile::{ImageRef, Variant};

    pub const ROWS: usize = 44;
    pub const COLS: usize = 44;
    /// The array's frame period: 100 Hz.
    pub const PERIOD_US: u32 = 10_000;
    const STANCE_US: u32 = 240_000;
    const FLIGHT_US: u32 = 200_000;

    /// The board's peripherals: the switch, the tactile array, the clock.
    pub struct Board {
        pub now_us: u32,
    }

    impl Board {
        /// The micro-switch (closed in stance).
        fn switch_closed(&self) -> bool {
            self.now_us % (STANCE_US + FLIGHT_US) < STANCE_US
        }

        /// Scans the array into `px` (8-bit counts): in stance the whole sole presses, most
        /// under the heel, with the load rising and falling over the stance; nothing in flight.
        fn scan(&self, px: &mut [u16; ROWS * COLS]) {
            let t = self.now_us % (STANCE_US + FLIGHT_US);
            px.fill(0);
            if t >= STANCE_US {
                return;
            }
            // Load in per mille: a triangle over the stance (integers: an M4 has no libm).
            let half = STANCE_US / 2;
            let load = if t < half { t } else { STANCE_US - t } as i32 * 1000 / half as i32;
            for (i, p) in px.iter_mut().enumerate() {
                let (y, x) = ((i / COLS) as i32 - 30, (i % COLS) as i32 - 22);
                let falloff = 1200 - (y * y + x * x).min(1200); // 0..1200, peak at the heel
                let texture = ((i * 7919) % 13) as i32; // the felt's grain
                *p = (10 + texture + load * falloff / 6000) as u16;
            }
        }
    }

    /// The main loop: every 10 ms the switch state, then the image sampled at that instant,
    /// both stamped with the board's clock. A board's loop never ends; this one returns the
    /// driver after `steps` stances, for the host.
    pub fn run<C: embedded_can::blocking::Can>(
        can: C,
        board: &mut Board,
        steps: u32,
        mut wait_tick: impl FnMut(&mut C, u32),
    ) -> Result<C, FootError<C::Error>>
    where
        C::Error: core::fmt::Debug,
    {
        let mut foot = Foot::new(can, 0, IdConfig::default(), Variant::Fd);
        let mut px = [0u16; ROWS * COLS];
        let mut was_stance = false;
        let mut stances = 0;
        loop {
            wait_tick(foot.can(), board.now_us);
            let stance = board.switch_closed();
            if stance && !was_stance {
                stances += 1;
            }
            if !stance && was_stance && stances >= steps {
                foot.contact(stance, board.now_us)?; // the last liftoff ends the last step
                return Ok(foot.into_inner());
            }
            was_stance = stance;
            board.scan(&mut px);
            let image = ImageRef {
                rows: ROWS,
                cols: COLS,
                bits: 8,
                timestamp_us: board.now_us,
                pixels: &px,
            };
            foot.tick(stance, board.now_us, Some(&image))?;
            board.now_us = board.now_us.wrapping_add(PERIOD_US);
        }
    }
}

/// Host driver 1: a candump `-L` log, stamped with the firmware's clock (plus 20 µs per frame,
/// the order the frames would leave the controller in).
struct CandumpLog<W: Write> {
    out: W,
    t_us: u64,
}

#[derive(Debug)]
struct LogError;
impl embedded_can::Error for LogError {
    fn kind(&self) -> embedded_can::ErrorKind {
        embedded_can::ErrorKind::Other
    }
}

impl<W: Write> embedded_can::blocking::Can for CandumpLog<W> {
    type Frame = CanFrame;
    type Error = LogError;
    fn transmit(&mut self, frame: &CanFrame) -> Result<(), LogError> {
        self.t_us += 20;
        let st = Stamped {
            t_us: self.t_us,
            frame: *frame,
        };
        candump::write_record(&mut self.out, "can0", &st).map_err(|_| LogError)
    }
    fn receive(&mut self) -> Result<CanFrame, LogError> {
        Err(LogError)
    }
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let steps: u32 = arg("--steps")
        .map(|s| s.parse().map_err(|_| format!("--steps {s}: not a number")))
        .transpose()?
        .unwrap_or(10);
    let mut board = firmware::Board { now_us: 0 };
    const LOG_START_US: u64 = 1_700_000_000_000_000;
    if let Some(path) = arg("--log") {
        let file =
            std::fs::File::create(&path).map_err(|e| format!("cannot create {path}: {e}"))?;
        let log = CandumpLog {
            out: std::io::BufWriter::new(file),
            t_us: LOG_START_US,
        };
        let mut log = firmware::run(log, &mut board, steps, |log, now| {
            log.t_us = LOG_START_US + now as u64;
        })
        .map_err(|e| format!("writing {path}: {e}"))?;
        log.out
            .flush()
            .map_err(|e| format!("writing {path}: {e}"))?;
        eprintln!("{steps} steps written to {path}");
    } else if let Some(iface) = arg("--iface") {
        use socketcan::Socket as _;
        let sock = socketcan::CanFdSocket::open(&iface)
            .map_err(|e| format!("cannot open {iface}: {e} (sudo ./vcan-setup.sh {iface})"))?;
        let start = std::time::Instant::now();
        firmware::run(sock, &mut board, steps, |_, now| {
            let due = std::time::Duration::from_micros(now as u64);
            if let Some(d) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(d);
            }
        })
        .map_err(|e| format!("sending on {iface}: {e}"))?;
        eprintln!("{steps} steps sent on {iface}");
    } else {
        return Err("give --log FILE (a candump log) or --iface IFACE (a CAN FD bus)".into());
    }
    Ok(())
}
