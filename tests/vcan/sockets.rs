//! Real SocketCAN sockets: every message through the kernel, FD and classic interfaces, a
//! missing interface, and the 100 Hz image stream with none lost.

use super::*;

#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn every_message_round_trips_through_the_kernel() {
    let _time = Timed(
        "every_message_round_trips_through_the_kernel",
        Instant::now(),
    );
    let ids = IdConfig::default();
    let iface = fd_iface();
    let mut tx = open(&iface);
    let mut rx = open(&iface);
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let mut sent = Vec::new();
    for foot in 0..8u8 {
        for m in random_messages(&mut rng, foot) {
            tx.send(&m.to_frame(&ids, foot).unwrap()).unwrap();
            sent.push((foot, m));
        }
    }
    let mut got = Vec::new();
    let mut last_t = 0;
    while got.len() < sent.len() {
        let st = rx
            .recv(Duration::from_secs(2))
            .unwrap()
            .expect("frame lost in the kernel");
        assert!(st.t_us >= last_t, "kernel timestamps go backwards");
        assert!(
            st.t_us > 1_600_000_000_000_000,
            "no kernel receive timestamp: {}",
            st.t_us
        );
        last_t = st.t_us;
        let (foot, m) = decode(&st.frame, &ids).unwrap().unwrap();
        got.push((foot, m));
    }
    for ((fa, a), (fb, b)) in sent.iter().zip(&got) {
        assert_eq!(a, b);
        if a.kind().per_foot() {
            assert_eq!(fa, fb);
        }
    }
    // Tactile segments: both variants through the kernel.
    for v in [Variant::Fd, Variant::Classic] {
        let px: Vec<u16> = (0..44 * 44).map(|_| rng.random_range(0..256)).collect();
        let frames = frames_44x44(&ids, v, 4, 9, 1, &px);
        for f in &frames {
            tx.send(f).unwrap();
        }
        let n = frames.len();
        let mut r = Reassembler::default();
        let mut img = None;
        for _ in 0..n {
            let st = rx
                .recv(Duration::from_secs(2))
                .unwrap()
                .expect("segment lost");
            assert_eq!(st.frame.is_fd(), v == Variant::Fd);
            assert_eq!(st.frame.is_brs(), v == Variant::Fd);
            let Ok(Some((foot, Message::TactileSegment(var)))) = decode(&st.frame, &ids) else {
                panic!("not tactile")
            };
            if let Some(i) = r.push(var, foot, st.frame.data(), st.t_us) {
                img = Some(i.pixels().to_vec());
            }
        }
        assert_eq!(img.as_deref(), Some(&px[..]), "{v:?}");
    }
}

#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn images_stream_at_100_hz_for_10_s_none_lost() {
    let _time = Timed("images_stream_at_100_hz_for_10_s_none_lost", Instant::now());
    let ids = IdConfig::default();
    let iface = fd_iface();
    let mut rx = open(&iface);
    rx.set_filters(&ids.filters(&[MessageKind::TactileFrame]))
        .unwrap();
    let tx_ids = ids.clone();
    let tx_iface = iface.clone();
    const N: usize = 1000;
    let sender = std::thread::spawn(move || {
        let mut tx = open(&tx_iface);
        let seg = Segmenter::new(Variant::Fd, tx_ids);
        let start = Instant::now();
        let mut px = vec![0u16; 44 * 44];
        for k in 0..N {
            for (i, p) in px.iter_mut().enumerate() {
                *p = ((i * 7 + k * 13) % 256) as u16;
            }
            seg.frames(
                0,
                k as u8,
                &ImageRef {
                    rows: 44,
                    cols: 44,
                    bits: 8,
                    timestamp_us: (k * 10_000) as u32,
                    pixels: &px,
                },
                &mut |f: protocol::CanFrame| {
                    // A full queue on vcan is transient: retry briefly, as a driver would.
                    let mut tries = 0;
                    while let Err(e) = tx.send(&f) {
                        tries += 1;
                        assert!(tries < 1000, "send failed: {e}");
                        std::thread::sleep(Duration::from_micros(100));
                    }
                },
            )
            .unwrap();
            let next = start + Duration::from_millis(10 * (k as u64 + 1));
            if let Some(d) = next.checked_duration_since(Instant::now()) {
                std::thread::sleep(d);
            }
        }
        start.elapsed()
    });
    let mut r = Reassembler::default();
    let mut delivered = 0;
    let mut wrong = 0;
    let deadline = Instant::now() + Duration::from_secs(60);
    while delivered < N && Instant::now() < deadline {
        let Some(st) = rx.recv(Duration::from_millis(500)).unwrap() else {
            continue;
        };
        if let Some(img) = r.push(Variant::Fd, 0, st.frame.data(), st.t_us) {
            let k = (img.timestamp_us / 10_000) as usize;
            if img
                .pixels()
                .iter()
                .enumerate()
                .any(|(i, p)| *p != ((i * 7 + k * 13) % 256) as u16)
            {
                wrong += 1;
            }
            delivered += 1;
        }
    }
    let took = sender.join().unwrap();
    println!(
        "streamed {delivered} images of 44x44 in {took:?}; reassembly stats {:?}",
        r.stats()
    );
    assert_eq!(wrong, 0);
    assert_eq!(delivered, N, "images lost: {:?}", r.stats());
    assert!(
        took >= Duration::from_millis(9_900),
        "not paced at 100 Hz: {took:?}"
    );
}

#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn fd_frames_on_a_classic_interface_get_a_clear_error() {
    let _time = Timed(
        "fd_frames_on_a_classic_interface_get_a_clear_error",
        Instant::now(),
    );
    let iface = classic_iface();
    assert_eq!(
        protocol::bus::interface_mtu(&iface),
        Some(16),
        "{iface} must be a classic (MTU 16) vcan"
    );
    let mut tx = open(&iface);
    let f = protocol::CanFrame::fd(
        protocol::frame::make_id(0x600, false).unwrap(),
        &[0; 64],
        true,
    )
    .unwrap();
    let e = tx.send(&f).unwrap_err();
    assert!(matches!(e, BusError::FdNotSupported { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("MTU 16") && msg.contains("mtu 72") && msg.contains("classic tactile variant"),
        "{msg}"
    );
    // Classic frames still go.
    let c = protocol::CanFrame::classic(protocol::frame::make_id(0x100, false).unwrap(), &[1; 8])
        .unwrap();
    tx.send(&c).unwrap();
}

#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn a_classic_socket_never_sees_fd_frames() {
    let _time = Timed("a_classic_socket_never_sees_fd_frames", Instant::now());
    use socketcan::{CanSocket, Socket};
    let iface = fd_iface();
    let classic = CanSocket::open(&iface).unwrap();
    classic
        .set_read_timeout(Duration::from_millis(300))
        .unwrap();
    let mut fd_rx = open(&iface);
    let mut tx = open(&iface);
    let f = protocol::CanFrame::fd(
        protocol::frame::make_id(0x600, false).unwrap(),
        &[3; 64],
        true,
    )
    .unwrap();
    tx.send(&f).unwrap();
    assert!(fd_rx.recv(Duration::from_secs(1)).unwrap().is_some());
    assert!(
        classic.read_frame().is_err(),
        "a classic CanSocket received an FD frame"
    );
}

#[test]
#[ignore = "needs vcan interfaces: tests/vcan/run.sh runs it"]
fn missing_interface_names_the_fix() {
    let _time = Timed("missing_interface_names_the_fix", Instant::now());
    let e = SocketCanBus::open("nosuchcan9")
        .err()
        .expect("opened a missing interface");
    let msg = e.to_string();
    assert!(
        msg.contains("nosuchcan9") && msg.contains("vcan-setup.sh"),
        "{msg}"
    );
}
