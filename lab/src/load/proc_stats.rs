//! A process's CPU time and resident memory, read from `/proc`.

/// The task folders of a process's threads (`pid` or "self"), all or those named in `names`.
fn tasks(pid: &str, names: Option<&[&str]>) -> Option<Vec<std::path::PathBuf>> {
    let dir = std::fs::read_dir(format!("/proc/{pid}/task")).ok()?;
    let named = |p: &std::path::Path| {
        names.is_none_or(|names| {
            let comm = std::fs::read_to_string(p.join("comm")).unwrap_or_default();
            names.contains(&comm.trim())
        })
    };
    Some(
        dir.flatten()
            .map(|e| e.path())
            .filter(|p| named(p))
            .collect(),
    )
}

/// Field `i` of a thread's schedstat (0: ns on a CPU, 2: times put on a CPU).
fn schedstat(task: &std::path::Path, i: usize) -> Option<u64> {
    let s = std::fs::read_to_string(task.join("schedstat")).ok()?;
    s.split_whitespace().nth(i)?.parse().ok()
}

/// CPU time (ns) of a process's threads (`pid` or "self"), all or those named in `names`: from
/// schedstat, or from stat's utime+stime (10 ms ticks) where schedstat is missing.
pub fn task_cpu_ns(pid: &str, names: Option<&[&str]>) -> Option<u64> {
    let mut total = 0u64;
    for p in tasks(pid, names)? {
        if let Some(ns) = schedstat(&p, 0) {
            total += ns;
            continue;
        }
        let stat = std::fs::read_to_string(p.join("stat")).ok()?;
        // Fields after the ")" of comm: state is field 3, utime 14, stime 15.
        let rest = stat.rsplit_once(')')?.1;
        let f: Vec<&str> = rest.split_whitespace().collect();
        let ticks = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
        total += ticks * 10_000_000;
    }
    Some(total)
}

/// How often the threads of a process (`pid` or "self") named in `names` were put on a CPU
/// (schedstat's third field: each wake-up from sleep is one): the wake-ups a node costs.
pub fn task_slices(pid: &str, names: &[&str]) -> Option<u64> {
    tasks(pid, Some(names))?
        .iter()
        .map(|p| schedstat(p, 2))
        .sum()
}

/// VmRSS and VmHWM (peak) of a process (`pid` or "self"), MB.
pub fn memory_mb(pid: &str) -> (Option<f64>, Option<f64>) {
    let Ok(s) = std::fs::read_to_string(format!("/proc/{pid}/status")) else {
        return (None, None);
    };
    let field = |k: &str| {
        s.lines()
            .find(|l| l.starts_with(k))
            .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
            .map(|kb| kb / 1024.0)
    };
    (field("VmRSS:"), field("VmHWM:"))
}
