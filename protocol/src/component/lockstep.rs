//! Every component on one simulated clock: [`LockStep`].

use std::sync::Arc;
use std::time::Duration;

use super::{Component, Outbox};
use crate::bus::{CanBus, InProcBus, InProcEndpoint};
use crate::clock::ManualClock;
use crate::emit::Emit;
use crate::error::BusError;
use crate::frame::Stamped;

/// Every component on one simulated clock, on one in-process bus: the demo's, the tests' and
/// the experiments' loop. Each [`LockStep::step`] sets the clock and gives each part, in a
/// fixed order, the frames queued for it and then its tick; what a part sends is on the bus
/// before the next part's turn. A run is the same on every machine for a seed, as fast as the
/// machine goes, and the parts talk only through frames, as they do as processes on vcan.
pub struct LockStep {
    clock: ManualClock,
    bus: InProcBus,
    endpoints: Vec<InProcEndpoint>,
    out: Outbox,
    t_us: u64,
    link_up: bool,
}

impl LockStep {
    /// A bus for `parts` parts (part `i` is the `i`-th of [`LockStep::step`]'s slice), each
    /// with a queue of `depth` frames, the clock at 0.
    pub fn new(parts: usize, depth: usize) -> Self {
        let clock = ManualClock::new(0);
        let bus = InProcBus::with_clock(Arc::new(clock.clone()), depth);
        let endpoints = (0..parts).map(|_| bus.endpoint()).collect();
        Self {
            clock,
            bus,
            endpoints,
            out: Outbox::with_capacity(256),
            t_us: 0,
            link_up: true,
        }
    }

    /// Part `i` (re)starts: its filters are set, frames queued for it are dropped (a new
    /// process hears only what comes after it), and it is [`Component::start`]ed now.
    pub fn start(
        &mut self,
        i: usize,
        part: &mut dyn Component,
        sent: &mut dyn Emit<Stamped>,
    ) -> Result<(), BusError> {
        let Some(ep) = self.endpoints.get_mut(i) else {
            return Ok(());
        };
        ep.set_filters(&part.filters())?;
        while ep.recv(Duration::ZERO)?.is_some() {}
        part.start(self.t_us, &mut self.out);
        self.send(i, sent)
    }

    /// Part `i` stops, as the other runners stop a part: [`Component::stop`] now, and what it
    /// sends last (a node's `Stopping` status, a leg bridge's motor stop frames) goes on the
    /// bus.
    pub fn stop(
        &mut self,
        i: usize,
        part: &mut dyn Component,
        sent: &mut dyn Emit<Stamped>,
    ) -> Result<(), BusError> {
        if i >= self.endpoints.len() {
            return Ok(());
        }
        part.stop(self.t_us, &mut self.out);
        self.send(i, sent)
    }

    /// Every part present [`LockStep::start`]s, in order (part `i` at index `i`).
    pub fn start_all(
        &mut self,
        parts: &mut [Option<&mut dyn Component>],
        sent: &mut dyn Emit<Stamped>,
    ) -> Result<(), BusError> {
        for (i, part) in parts.iter_mut().enumerate() {
            if let Some(p) = part {
                self.start(i, *p, sent)?;
            }
        }
        Ok(())
    }

    /// Every part present [`LockStep::stop`]s, the last first: the parts nearest the motors
    /// stop before those that command them.
    pub fn stop_all(
        &mut self,
        parts: &mut [Option<&mut dyn Component>],
        sent: &mut dyn Emit<Stamped>,
    ) -> Result<(), BusError> {
        for (i, part) in parts.iter_mut().enumerate().rev() {
            if let Some(p) = part {
                self.stop(i, *p, sent)?;
            }
        }
        Ok(())
    }

    /// While the link is down every frame sent is lost, as on an interface that is down (the
    /// observer of [`LockStep::step`] still sees it: the sender did send it).
    pub fn set_link(&mut self, up: bool) {
        self.link_up = up;
    }

    /// Moves the clock to `t_us` and runs each part in order: its frames, then its tick. A
    /// part that is `None` (a process killed) loses what was queued for it. `sent` sees every
    /// frame sent, with the time.
    pub fn step(
        &mut self,
        t_us: u64,
        parts: &mut [Option<&mut dyn Component>],
        sent: &mut dyn Emit<Stamped>,
    ) -> Result<(), BusError> {
        self.t_us = t_us;
        self.clock.set_us(t_us);
        for (i, part) in parts.iter_mut().enumerate() {
            let Some(ep) = self.endpoints.get_mut(i) else {
                break;
            };
            match part {
                None => while ep.recv(Duration::ZERO)?.is_some() {},
                Some(p) => {
                    while let Some(st) = ep.recv(Duration::ZERO)? {
                        p.on_frame(&st, t_us, &mut self.out);
                    }
                    p.tick(t_us, &mut self.out);
                    self.send(i, sent)?;
                }
            }
        }
        Ok(())
    }

    fn send(&mut self, i: usize, sent: &mut dyn Emit<Stamped>) -> Result<(), BusError> {
        let (t, up) = (self.t_us, self.link_up);
        let ep = &mut self.endpoints[i];
        for f in self.out.drain() {
            sent.emit(Stamped { t_us: t, frame: f });
            if up {
                ep.send(&f)?;
            }
        }
        Ok(())
    }

    /// Frames dropped because a part's queue was full.
    pub fn overruns(&self) -> u64 {
        self.bus.overruns()
    }
}
