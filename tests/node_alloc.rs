//! The node's hot path allocates nothing, with or without the ROS 2 bridge beside it on the
//! same bus, and keeping its unknown stances: a counting allocator counts every allocation made on the node's thread
//! (`pipeline`) while four feet stream at 100 Hz, after the warm-up. Nor does the
//! controller's (command in, motor frame out: a hop's messages in, LegCommand, StepState and
//! GaitStatus out), counted on its own thread (`controller-hot-path`).

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

struct Counting;

static ARMED: AtomicBool = AtomicBool::new(false);
static COUNT: AtomicU64 = AtomicU64::new(0);
static CTRL_ARMED: AtomicBool = AtomicBool::new(false);
static CTRL_COUNT: AtomicU64 = AtomicU64::new(0);

thread_local! {
    // 0: not known yet, 1: the node's thread, 2: another, 3: the controller's.
    static WHO: Cell<u8> = const { Cell::new(0) };
    static ASKING: Cell<bool> = const { Cell::new(false) };
}

fn count() {
    let _ = WHO.try_with(|who| {
        if who.get() == 0 {
            // Naming the thread may allocate: not counted, and not asked again meanwhile.
            if ASKING.with(|a| a.replace(true)) {
                return;
            }
            let kind = match std::thread::current().name() {
                Some("pipeline") => 1,
                Some("controller-hot-path") => 3,
                _ => 2,
            };
            who.set(kind);
            ASKING.with(|a| a.set(false));
        }
        if who.get() == 1 && ARMED.load(Ordering::Relaxed) {
            COUNT.fetch_add(1, Ordering::Relaxed);
        }
        if who.get() == 3 && CTRL_ARMED.load(Ordering::Relaxed) {
            CTRL_COUNT.fetch_add(1, Ordering::Relaxed);
        }
    });
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc_zeroed(l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static A: Counting = Counting;

/// Allocations on the node's thread from 2 s into a 5 s run (1 s of it warm-up).
fn node_allocations(bridge: bool, keep: bool, dir: &std::path::Path) -> u64 {
    let model = if keep {
        common::model_without("clay")
    } else {
        node::classifier::Model::load(&small_model(dir)).unwrap()
    };
    let kept = dir.join(format!("kept-{}", std::process::id()));
    let keep = keep.then_some(kept.as_path());
    let feet =
        lab::load::Feet::new(4, lab::load::image_pool(), protocol::IdConfig::default()).unwrap();
    let beside = bridge.then(|| {
        let opts = ros2::Ros2Options {
            ros2_bag: Some(dir.join(format!("bag-{}", std::process::id()))),
            ..Default::default()
        };
        let out = opts
            .start(
                &protocol::IdConfig::default(),
                &protocol::TerrainCatalog::paper(),
                false,
            )
            .unwrap()
            .unwrap();
        Box::new(out) as Box<dyn record::FrameConsumer>
    });
    COUNT.store(0, Ordering::Relaxed);
    let arm = std::thread::spawn(|| {
        std::thread::sleep(Duration::from_secs(2));
        ARMED.store(true, Ordering::Relaxed);
        std::thread::sleep(Duration::from_secs(2));
        ARMED.store(false, Ordering::Relaxed);
    });
    let run = lab::load::bench_inproc(
        model,
        feet,
        5_000_000,
        None,
        node::NodeThreads::One,
        beside,
        keep,
    )
    .unwrap();
    arm.join().unwrap();
    assert!(run.tally.steps > 0, "the node decided no step");
    if keep.is_some() {
        let written = run.extra["kept_unknown"]["written"].as_u64().unwrap();
        assert!(written > 0, "nothing kept: {}", run.extra);
    }
    COUNT.load(Ordering::Relaxed)
}

fn small_model(dir: &std::path::Path) -> std::path::PathBuf {
    let p = dir.join("model.json");
    if !p.exists() {
        let m = lab::model::load_or_train_logged(None).unwrap();
        m.save(&p).unwrap();
    }
    p
}

#[test]
fn the_node_allocates_nothing_per_frame_with_or_without_the_bridge_or_keeping_unknown_stances() {
    let dir = std::env::temp_dir().join(format!("presrs-node-alloc-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // The counter itself: it sees an allocation on a thread of the node's name.
    ARMED.store(true, Ordering::Relaxed);
    std::thread::Builder::new()
        .name("pipeline".into())
        .spawn(|| std::hint::black_box(vec![1u8; 64]).len())
        .unwrap()
        .join()
        .unwrap();
    ARMED.store(false, Ordering::Relaxed);
    assert!(
        COUNT.load(Ordering::Relaxed) > 0,
        "the counting allocator counts nothing"
    );
    let without = node_allocations(false, false, &dir);
    let with = node_allocations(true, false, &dir);
    let keeping = node_allocations(false, true, &dir);
    eprintln!(
        "allocations on the node's thread over 2 s: {without} alone, {with} with the bridge, \
         {keeping} keeping unknown stances"
    );
    assert_eq!(
        keeping, 0,
        "the node's hot path allocates keeping unknown stances"
    );
    assert_eq!(without, 0, "the node's hot path allocates");
    assert_eq!(
        with, 0,
        "the node's hot path allocates with the bridge beside it"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The controller's hot path: 20 s of a simulated hop's bus (FootContact, LegState, the node's
/// TerrainClass after each touchdown, alternating wood and clay so the gait switches, its
/// heartbeat), recorded first, then fed to a controller on a thread of its own; allocations
/// counted after the first 3 s (its takeover and first gait).
#[test]
fn the_controllers_hot_path_allocates_nothing() {
    use protocol::messages::{Message, NodeStatus, TerrainClass, decode};
    let catalog = protocol::TerrainCatalog::paper();
    let ids = protocol::IdConfig::default();
    let mut robot = sim::runner::SimRobot::new(sim::runner::SimConfig::default(), 1);
    let mut bus: Vec<(u64, u8, Message)> = Vec::new();
    let (mut frames, mut said) = (Vec::new(), 0usize);
    let mut t = 0u64;
    while t < 20_000_000 {
        t += 1_000;
        frames.clear();
        robot.advance_to(t, &mut frames);
        for f in &frames {
            if let Ok(Some((foot, m))) = decode(f, &ids) {
                bus.push((t, foot, m));
            }
        }
        while robot
            .steps
            .get(said)
            .is_some_and(|s| s.touchdown_us + 70_000 <= t)
        {
            let name = if (said / 6) % 2 == 0 { "wood" } else { "clay" };
            let tc = TerrainClass {
                step: said as u16,
                terrain: catalog.by_name(name).unwrap().id(),
                confidence_pct: 99.0,
                ..TerrainClass::default()
            };
            bus.push((t, 0, Message::TerrainClass(tc)));
            said += 1;
        }
        if t.is_multiple_of(100_000) {
            bus.push((t, 0, Message::NodeStatus(NodeStatus::default())));
        }
    }
    // The counter itself: it sees an allocation on a thread of the controller's name.
    let on_controller_thread = |f: fn()| {
        std::thread::Builder::new()
            .name("controller-hot-path".into())
            .spawn(f)
            .unwrap()
            .join()
            .unwrap()
    };
    on_controller_thread(|| {
        CTRL_ARMED.store(true, Ordering::Relaxed);
        std::hint::black_box(vec![1u8; 64]);
        CTRL_ARMED.store(false, Ordering::Relaxed);
    });
    assert!(
        CTRL_COUNT.swap(0, Ordering::Relaxed) > 0,
        "the counter counts nothing"
    );
    let (counted, sent, switches) = std::thread::Builder::new()
        .name("controller-hot-path".into())
        .spawn(move || {
            let mut c =
                controller::Controller::new(controller::ControllerConfig::default(), &catalog);
            // What it sends, counted by kind into fixed slots: nothing to grow.
            let mut sent = [0u64; 3];
            let mut sink = |m: Message| match m {
                Message::LegCommand(_) => sent[0] += 1,
                Message::StepState(_) => sent[1] += 1,
                Message::GaitStatus(_) => sent[2] += 1,
                _ => {}
            };
            let mut next_tick = 0u64;
            for (t, foot, m) in &bus {
                CTRL_ARMED.store(*t >= 3_000_000, Ordering::Relaxed);
                while next_tick <= *t {
                    c.tick(next_tick, &mut sink);
                    next_tick += 1_000;
                }
                c.on_message(*foot, m, *t, &mut sink);
            }
            CTRL_ARMED.store(false, Ordering::Relaxed);
            (CTRL_COUNT.load(Ordering::Relaxed), sent, c.switches)
        })
        .unwrap()
        .join()
        .unwrap();
    eprintln!(
        "controller: {counted} allocations after the first 3 s; sent {} LegCommand, {} StepState, {} GaitStatus; {switches} gait switches",
        sent[0], sent[1], sent[2]
    );
    assert!(
        sent[0] > 1_000 && sent[1] > 20 && switches >= 4,
        "{sent:?} {switches}"
    );
    assert_eq!(counted, 0, "the controller's hot path allocates");
}
