//! SocketCAN through the `socketcan` crate: one `CanFdSocket` per handle, kernel receive
//! timestamps, kernel-side filters.

use std::io::ErrorKind;
use std::time::{Duration, UNIX_EPOCH};

use socketcan::errors::ControllerProblems;
use socketcan::id::FdFlags;
use socketcan::{
    CanAnyFrame, CanErrorFrame, CanFdFrame, CanFdSocket, CanFilter, EmbeddedFrame, Socket,
    SocketOptions,
};

use super::{BusHealth, CanBus, ErrorClasses};
use crate::error::BusError;
use crate::frame::{CanFrame, Stamped};

/// Receive buffer requested per socket.
pub const RECV_BUFFER_BYTES: usize = 4 << 20;

/// A handle on a Linux CAN interface (`can0`, `vcan0`, ...).
///
/// The socket is an FD socket, so it receives classic and FD frames alike. On an interface with
/// MTU 16 (classic only) sending an FD frame fails with [`BusError::FdNotSupported`]; note that a
/// classic `CanSocket` elsewhere on the host never sees FD frames.
pub struct SocketCanBus {
    iface: String,
    sock: CanFdSocket,
    /// Set non-blocking for receiving (see `recv`).
    nonblocking: bool,
    health: BusHealth,
}

fn force_recv_buffer(sock: &CanFdSocket, bytes: usize) -> bool {
    use std::os::fd::AsRawFd;
    let v = bytes as libc::c_int;
    // SAFETY: a valid socket fd and a c_int option value of the right size.
    let r = unsafe {
        libc::setsockopt(
            sock.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_RCVBUFFORCE,
            &v as *const libc::c_int as *const libc::c_void,
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        )
    };
    r == 0
}

/// The interface's MTU from sysfs: 16 for classic CAN, 72 for CAN FD.
pub fn interface_mtu(iface: &str) -> Option<u32> {
    std::fs::read_to_string(format!("/sys/class/net/{iface}/mtu"))
        .ok()
        .and_then(|s| s.trim().parse().ok())
}

impl SocketCanBus {
    /// Opens `iface` (`can0`, `vcan0`) with CAN FD frames enabled when the interface carries them.
    pub fn open(iface: &str) -> Result<Self, BusError> {
        let open_err = |source| BusError::Open {
            iface: iface.to_string(),
            source,
        };
        let sock = CanFdSocket::open(iface).map_err(open_err)?;
        sock.set_recv_timestamp(true).map_err(open_err)?;
        // Every error class: bus-off and error-passive are what a robot must know first.
        sock.set_error_filter_accept_all().map_err(open_err)?;
        // A full transmit queue (no ACK, bus off) must not stall a control loop.
        sock.set_write_timeout(Duration::from_millis(5))
            .map_err(open_err)?;
        // One tactile image is a burst of 33 FD (or 391 classic) frames per foot; the default
        // receive buffer (~200 KiB, a few hundred frames) overflows when a reader is briefly late.
        // SO_RCVBUFFORCE (needs CAP_NET_ADMIN) passes net.core.rmem_max; otherwise the kernel
        // caps the plain request at rmem_max.
        if !force_recv_buffer(&sock, RECV_BUFFER_BYTES) {
            let _ = sock.as_raw_socket().set_recv_buffer_size(RECV_BUFFER_BYTES);
        }
        Ok(Self {
            iface: iface.to_string(),
            sock,
            nonblocking: false,
            health: BusHealth::default(),
        })
    }

    /// The interface name.
    pub fn iface(&self) -> &str {
        &self.iface
    }

    /// Waits up to `left` for the socket to be readable (or to have an error to report):
    /// false after the wait without it, or on a signal.
    fn wait_readable(&self, left: Duration) -> Result<bool, BusError> {
        use std::os::fd::AsRawFd;
        let mut pfd = libc::pollfd {
            fd: self.sock.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        let ts = libc::timespec {
            tv_sec: left.as_secs().min(i32::MAX as u64) as libc::time_t,
            tv_nsec: left.subsec_nanos() as libc::c_long,
        };
        // SAFETY: one valid pollfd, a valid timespec, no signal mask.
        let r = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
        if r < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() == ErrorKind::Interrupted {
                return Ok(false);
            }
            return Err(self.io_err(e));
        }
        Ok(r > 0)
    }

    fn io_err(&self, e: std::io::Error) -> BusError {
        let iface = self.iface.clone();
        match e.raw_os_error() {
            // The interface is down or gone.
            Some(libc::ENETDOWN | libc::ENODEV | libc::ENXIO) => {
                BusError::Down { iface, source: e }
            }
            Some(libc::ENOBUFS) => BusError::TxQueueFull { iface },
            _ if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::TimedOut => {
                BusError::TxQueueFull { iface }
            }
            _ => BusError::Io { iface, source: e },
        }
    }
}

fn to_socketcan(f: &CanFrame) -> Option<CanAnyFrame> {
    if f.is_fd() {
        let flags = if f.is_brs() {
            FdFlags::BRS
        } else {
            FdFlags::empty()
        };
        CanFdFrame::with_flags(f.id(), f.data(), flags).map(CanAnyFrame::Fd)
    } else if f.is_remote() {
        socketcan::CanRemoteFrame::new_remote(f.id(), f.len()).map(CanAnyFrame::Remote)
    } else {
        socketcan::CanDataFrame::new(f.id(), f.data()).map(CanAnyFrame::Normal)
    }
}

fn from_socketcan(f: &CanAnyFrame) -> Option<CanFrame> {
    match f {
        CanAnyFrame::Normal(d) => CanFrame::classic(d.id(), d.data()),
        CanAnyFrame::Remote(r) => CanFrame::remote(r.id(), r.dlc()),
        CanAnyFrame::Fd(d) => CanFrame::fd(d.id(), d.data(), d.is_brs()),
        CanAnyFrame::Error(_) => None,
    }
}

/// The classes of a kernel error frame, decoded by the `socketcan` crate.
fn error_classes(f: CanErrorFrame) -> ErrorClasses {
    let e = f.into_error();
    let ctrl = e.controller().unwrap_or(ControllerProblems::empty());
    ErrorClasses {
        tx_timeout: e.is_transmit_timeout(),
        lost_arbitration: e.lost_arbitration().is_some(),
        warning: ctrl.intersects(ControllerProblems::RX_WARNING | ControllerProblems::TX_WARNING),
        passive: ctrl.intersects(ControllerProblems::RX_PASSIVE | ControllerProblems::TX_PASSIVE),
        active: ctrl.contains(ControllerProblems::ACTIVE),
        overflow: ctrl
            .intersects(ControllerProblems::RX_OVERFLOW | ControllerProblems::TX_OVERFLOW),
        protocol: e.protocol().is_some(),
        transceiver: e.transceiver().is_some(),
        no_ack: e.is_no_ack(),
        bus_off: e.is_bus_off(),
        bus_error: e.is_bus_error(),
        restarted: e.is_restarted(),
        counters: e.counters(),
    }
}

/// Writes a kernel error frame of `class_bits` (`CAN_ERR_*` of `linux/can/error.h`) with `data`
/// to `iface`, as `cansend IFACE 2000xxxx#...` does: every socket with an error mask on a
/// virtual interface hears it. For fault drills and tests; a real controller sends its own.
pub fn send_error_frame(iface: &str, class_bits: u32, data: &[u8]) -> Result<(), BusError> {
    let io = |source| BusError::Io {
        iface: iface.to_string(),
        source,
    };
    let f = CanErrorFrame::new_error(class_bits, data)
        .map_err(|e| io(std::io::Error::new(ErrorKind::InvalidInput, format!("{e}"))))?;
    let sock = CanFdSocket::open(iface).map_err(|source| BusError::Open {
        iface: iface.to_string(),
        source,
    })?;
    sock.write_frame(&CanAnyFrame::Error(f)).map_err(io)
}

impl CanBus for SocketCanBus {
    fn send(&mut self, frame: &CanFrame) -> Result<(), BusError> {
        let Some(f) = to_socketcan(frame) else {
            return Err(BusError::Io {
                iface: self.iface.clone(),
                source: std::io::Error::new(ErrorKind::InvalidInput, "frame not representable"),
            });
        };
        match self.sock.write_frame(&f) {
            Ok(()) => Ok(()),
            // The kernel answers EINVAL to an FD frame on an MTU-16 interface.
            Err(e) if frame.is_fd() && e.raw_os_error() == Some(libc::EINVAL) => {
                Err(BusError::FdNotSupported {
                    iface: self.iface.clone(),
                })
            }
            Err(e) => Err(self.io_err(e)),
        }
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Stamped>, BusError> {
        // The wait is ppoll(2)'s, on the kernel's high-resolution timers, then a non-blocking
        // read. SO_RCVTIMEO rounds a wait up to a scheduler tick (4 ms on a HZ=250 kernel: a
        // simulator ticking every 300 us ran at half speed), and the socketcan crate sets it in
        // whole microseconds, so that a wait under 1 us read as 0, "wait forever" (measured in
        // the vcan VM: `presrs lab sim` blocked in recv for minutes on a bus with no frame for it).
        if !self.nonblocking {
            self.sock
                .set_nonblocking(true)
                .map_err(|e| self.io_err(e))?;
            self.nonblocking = true;
        }
        let deadline = std::time::Instant::now() + timeout;
        loop {
            match self.sock.read_frame_with_timestamp() {
                Ok((f, ts)) => {
                    let t_us = ts
                        .duration_since(UNIX_EPOCH)
                        .map(|d| d.as_micros() as u64)
                        .unwrap_or(0);
                    if let CanAnyFrame::Error(e) = f {
                        self.health.on_error_frame(&error_classes(e), t_us);
                        continue;
                    }
                    let Some(frame) = from_socketcan(&f) else {
                        continue;
                    };
                    self.health.on_traffic(t_us);
                    return Ok(Some(Stamped { t_us, frame }));
                }
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    let left = deadline.saturating_duration_since(std::time::Instant::now());
                    if left.is_zero() || !self.wait_readable(left)? {
                        return Ok(None);
                    }
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => return Ok(None),
                Err(e) => return Err(self.io_err(e)),
            }
        }
    }

    fn set_filters(&mut self, filters: &[(u32, u32)]) -> Result<(), BusError> {
        let r = if filters.is_empty() {
            self.sock.set_filter_accept_all()
        } else {
            let fs: Vec<CanFilter> = filters
                .iter()
                .map(|&(id, mask)| CanFilter::new(id, mask))
                .collect();
            self.sock.set_filters(&fs)
        };
        r.map_err(|e| self.io_err(e))
    }

    fn try_clone(&self) -> Result<Box<dyn CanBus>, BusError> {
        Ok(Box::new(SocketCanBus::open(&self.iface)?))
    }

    fn name(&self) -> &str {
        &self.iface
    }

    fn health(&self) -> BusHealth {
        self.health
    }
}
