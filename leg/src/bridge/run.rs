//! Running the bridge: on one bus (`presrs leg`), or with the motors on a bus of their own.

use super::{
    Component, Driver, IdConfig, LegConfig, LegCounters, LegMode, LegService, LegStatus, Message,
    MessageKind, Outbox, Stamped,
};

/// Runs the bridge on `source` until `stop` (`presrs leg`), on the robot's clock (`time_scale`
/// times the wall clock: match a simulator slower than real time). The motors share the bus
/// LegCommand comes on; a config with its own `motor_iface` is refused by the caller for now.
/// Returns the counters.
pub fn run(
    cfg: LegConfig,
    check: bool,
    source: &protocol::bus::BusSource,
    time_scale: f64,
    stop: &std::sync::atomic::AtomicBool,
) -> LegCounters {
    let mut leg = LegService::new(cfg, check);
    let opts = protocol::component::RunOptions {
        time_scale,
        ..protocol::component::RunOptions::default()
    };
    protocol::component::run(&mut leg, source, &opts, stop);
    leg.counters()
}

/// The bridge with its motors on a bus of their own (`motor_iface`): LegCommand, LegState and
/// LegStatus on `main`, the drivers on `motors`. One bridge, two runners on one robot clock:
/// the motor side receives the drivers and ticks (the commands go out on its bus), the main
/// side hands it LegCommand and sends what it says about the leg. Returns the counters.
pub fn run_two_buses(
    cfg: LegConfig,
    check: bool,
    main: &protocol::bus::BusSource,
    motors: &protocol::bus::BusSource,
    time_scale: f64,
    stop: &std::sync::atomic::AtomicBool,
) -> LegCounters {
    use std::sync::{Arc, Mutex};
    let ids = cfg.ids.clone();
    let foot = cfg.foot;
    let leg = Arc::new(Mutex::new(LegService::new(cfg, check)));
    // LegState at 500 Hz and LegStatus at 10 Hz: a second of them.
    let (tx, rx) = std::sync::mpsc::sync_channel(1024);
    let opts = protocol::component::RunOptions {
        clock: Some(Arc::new(protocol::clock::ScaledClock::new(time_scale))),
        ..protocol::component::RunOptions::default()
    };
    std::thread::scope(|s| {
        let mut main_side = MainSide {
            leg: leg.clone(),
            rx,
            ids: ids.clone(),
            foot,
        };
        let opts_main = opts.clone();
        s.spawn(move || protocol::component::run(&mut main_side, main, &opts_main, stop));
        let mut motor_side = MotorSide {
            leg: leg.clone(),
            tx,
            ids,
            scratch: Outbox::with_capacity(16),
        };
        protocol::component::run(&mut motor_side, motors, &opts, stop);
    });
    // Both runners have ended: the lock is free unless one of them panicked mid-call.
    leg.lock().map(|l| l.counters()).unwrap_or_default()
}

/// The bridge's side on the controller's bus.
pub(super) struct MainSide {
    leg: std::sync::Arc<std::sync::Mutex<LegService>>,
    rx: std::sync::mpsc::Receiver<protocol::CanFrame>,
    ids: IdConfig,
    foot: u8,
}

impl Component for MainSide {
    fn name(&self) -> &'static str {
        "leg (main bus)"
    }
    fn filters(&self) -> Vec<(u32, u32)> {
        vec![self.ids.foot_filter(MessageKind::LegCommand, self.foot)]
    }
    fn on_frame(&mut self, st: &Stamped, now_us: u64, out: &mut Outbox) {
        if let Ok(mut leg) = self.leg.lock() {
            leg.on_frame(st, now_us, out);
        }
    }
    fn tick(&mut self, _now_us: u64, out: &mut Outbox) {
        while let Ok(f) = self.rx.try_recv() {
            out.push(f);
        }
    }
    fn stop(&mut self, now_us: u64, out: &mut Outbox) {
        // The motor side stops the motors; the bus the controller reads hears it here.
        while let Ok(f) = self.rx.try_recv() {
            out.push(f);
        }
        if let Ok(leg) = self.leg.lock() {
            let status = LegStatus {
                mode: LegMode::Stopped,
                ..leg.status(now_us)
            };
            if let Some(f) = Message::LegStatus(status).to_frame(&self.ids, self.foot) {
                out.push(f);
            }
        }
    }
    fn is_own(&self, frame: &protocol::CanFrame) -> bool {
        matches!(
            self.ids.lookup(frame.raw_id(), frame.is_extended()),
            Some((MessageKind::LegState | MessageKind::LegStatus, f)) if f == self.foot
        )
    }
}

/// The bridge's side on the motors' bus.
pub(super) struct MotorSide {
    leg: std::sync::Arc<std::sync::Mutex<LegService>>,
    tx: std::sync::mpsc::SyncSender<protocol::CanFrame>,
    ids: IdConfig,
    scratch: Outbox,
}

impl MotorSide {
    /// Motor frames to `out`; ours (LegState, LegStatus) to the main bus (dropped, never
    /// waited for, when its side is behind: the next one follows in 2 ms).
    fn split(&mut self, out: &mut Outbox) {
        for f in self.scratch.drain() {
            if self.ids.lookup(f.raw_id(), f.is_extended()).is_some() {
                let _ = self.tx.try_send(f);
            } else {
                out.push(f);
            }
        }
    }
}

impl Component for MotorSide {
    fn name(&self) -> &'static str {
        "leg"
    }
    fn filters(&self) -> Vec<(u32, u32)> {
        match self.leg.lock() {
            Ok(leg) => leg.drivers.iter().flat_map(Driver::filters).collect(),
            Err(_) => Vec::new(),
        }
    }
    fn start(&mut self, now_us: u64, out: &mut Outbox) {
        if let Ok(mut leg) = self.leg.lock() {
            leg.start(now_us, &mut self.scratch);
        }
        self.split(out);
    }
    fn on_frame(&mut self, st: &Stamped, now_us: u64, out: &mut Outbox) {
        if let Ok(mut leg) = self.leg.lock() {
            leg.on_frame(st, now_us, &mut self.scratch);
        }
        self.split(out);
    }
    fn tick(&mut self, now_us: u64, out: &mut Outbox) {
        if let Ok(mut leg) = self.leg.lock() {
            leg.tick(now_us, &mut self.scratch);
        }
        self.split(out);
    }
    fn stop(&mut self, now_us: u64, out: &mut Outbox) {
        if let Ok(mut leg) = self.leg.lock() {
            leg.stop(now_us, &mut self.scratch);
        }
        self.split(out);
    }
}

#[cfg(test)]
mod two_bus_tests {
    use super::*;
    use crate::simulated::SimulatedLeg;
    use protocol::bus::{BusSource, CanBus, InProcBus};
    use protocol::messages::{LegCommand, LegState, Phase, decode};
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::{Duration, Instant};

    #[test]
    fn on_two_buses_commands_and_leg_state_stay_on_one_and_the_motors_on_the_other() {
        let text = crate::config::LegConfig::example(crate::DriverKind::Mit)
            .to_toml()
            .unwrap()
            .replace("foot = 0", "foot = 0\nmotor_iface = \"motors\"");
        let cfg = LegConfig::from_text(&text, "leg.toml").unwrap();
        let (main, motors) = (InProcBus::new(), InProcBus::new());
        let stop = AtomicBool::new(false);
        let ids = IdConfig::default();
        let truth = (0.2, 0.15);
        std::thread::scope(|s| {
            let (c, m, mo) = (cfg.clone(), main.clone(), motors.clone());
            let stop = &stop;
            s.spawn(move || {
                run_two_buses(
                    c,
                    false,
                    &BusSource::InProc(m),
                    &BusSource::InProc(mo),
                    1.0,
                    stop,
                )
            });
            // The motors: answer on their bus until stopped; say what they were told.
            let mut ep = motors.endpoint();
            let c2 = cfg.clone();
            let ids2 = ids.clone();
            let motor_side = s.spawn(move || {
                let ids = ids2;
                let mut sim = SimulatedLeg::new(&c2, 1);
                let (t0, mut ours_heard) = (Instant::now(), 0);
                let mut last = 0;
                // The set point while driven (at the end the leg is in the damped stop).
                let mut driven = None;
                while !stop.load(Ordering::Relaxed) {
                    if let Ok(Some(st)) = ep.recv(Duration::from_millis(1)) {
                        if ids
                            .lookup(st.frame.raw_id(), st.frame.is_extended())
                            .is_some()
                        {
                            ours_heard += 1;
                        }
                        sim.on_frame(&st.frame);
                        let sp = sim.set_point();
                        if sp.stiffness_n_per_m > 0.0 {
                            driven = Some(sp);
                        }
                    }
                    let now = t0.elapsed().as_micros() as u64;
                    if now >= last + 1000 {
                        let mut out = Outbox::default();
                        sim.emit(now, truth.0, truth.1, (now - last) as f64 * 1e-6, &mut out);
                        last = now;
                        for f in out.drain() {
                            let _ = ep.send(&f);
                        }
                    }
                }
                (sim.commanded, driven, ours_heard)
            });
            // The controller's side: LegCommand every 2 ms for 0.3 s, then silence.
            let mut ep = main.endpoint();
            let mut heard = Vec::new();
            let t0 = Instant::now();
            let mut seq = 0u8;
            // 0.6 s of wall time, and longer if that has not shown 50 LegState yet: at 500 Hz
            // it is about 300, but a loaded test machine starves the threads (47 in 0.6 s once,
            // beside a release build on both cores). A wall-clock window judges the machine.
            let is_state = |f: &protocol::CanFrame| {
                matches!(decode(f, &ids), Ok(Some((_, Message::LegState(_)))))
            };
            let mut states_heard = 0usize;
            while t0.elapsed() < Duration::from_millis(600)
                || (states_heard <= 50 && t0.elapsed() < Duration::from_secs(20))
            {
                if t0.elapsed() < Duration::from_millis(300) {
                    seq = seq.wrapping_add(1);
                    let f = Message::LegCommand(LegCommand {
                        leg_length_m: truth.1,
                        touchdown_angle_rad: truth.0,
                        gait: 2,
                        phase: Phase::Flight,
                        seq,
                    })
                    .to_frame(&ids, 0)
                    .unwrap();
                    let _ = ep.send(&f);
                }
                let until = Instant::now() + Duration::from_millis(2);
                while let Ok(Some(st)) = ep.recv(until.saturating_duration_since(Instant::now())) {
                    states_heard += is_state(&st.frame) as usize;
                    heard.push(st.frame);
                }
            }
            stop.store(true, Ordering::Relaxed);
            let (commanded, sp, ours_on_motor_bus) = motor_side.join().unwrap();
            assert!(commanded, "the motors were never commanded");
            let sp = sp.expect("the motors were never sprung");
            assert!((sp.length_m - truth.1).abs() < 1e-3, "{sp:?}");
            assert_eq!(
                ours_on_motor_bus, 0,
                "LegState/LegStatus/LegCommand on the motor bus"
            );
            let msgs: Vec<Message> = heard
                .iter()
                .filter_map(|f| decode(f, &ids).ok().flatten().map(|(_, m)| m))
                .collect();
            assert_eq!(msgs.len(), heard.len(), "motor frames on the main bus");
            let states: Vec<&LegState> = msgs
                .iter()
                .filter_map(|m| match m {
                    Message::LegState(s) => Some(s),
                    _ => None,
                })
                .collect();
            assert!(states.len() > 50, "{} LegState", states.len());
            let last = states[states.len() - 1];
            assert!((last.leg_length_m - truth.1).abs() < 0.002, "{last:?}");
            let modes: Vec<LegMode> = msgs
                .iter()
                .filter_map(|m| match m {
                    Message::LegStatus(s) => Some(s.mode),
                    _ => None,
                })
                .collect();
            assert!(modes.contains(&LegMode::Running), "{modes:?}");
            assert!(modes.contains(&LegMode::CommandTimeout), "{modes:?}");
        });
    }
}
