//! The node's hot path allocates nothing, with or without the ROS 2 bridge beside it on the
//! same bus, and keeping its unknown stances: a counting allocator counts every allocation made on the node's thread
//! (`pipeline`) while four feet stream at 100 Hz, after the warm-up.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

struct Counting;

static ARMED: AtomicBool = AtomicBool::new(false);
static COUNT: AtomicU64 = AtomicU64::new(0);

thread_local! {
    // 0: not known yet, 1: the node's thread, 2: another.
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
            let node = std::thread::current().name() == Some("pipeline");
            who.set(if node { 1 } else { 2 });
            ASKING.with(|a| a.set(false));
        }
        if who.get() == 1 && ARMED.load(Ordering::Relaxed) {
            COUNT.fetch_add(1, Ordering::Relaxed);
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
