//! The Slurm path for real: a single-node cluster on this machine
//! (`examples/slurm/local-cluster.sh`: munge, slurmctld and slurmd with a generated
//! slurm.conf), the job array and dependent merge of `examples/slurm/submit.sh` for the demo
//! city, and the merged file compared byte for byte with a bake on one machine. The daemons
//! are stopped at the end, also when the test fails.
//!
//! Needs Debian's `slurm-wlm` and `munge`: with `CI=true` the test installs them with apt-get
//! when they are missing (and fails if it cannot); elsewhere, without them, it prints why and
//! skips.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn found(bin: &str) -> bool {
    ["/usr/bin", "/usr/sbin", "/usr/local/bin", "/usr/local/sbin"]
        .iter()
        .any(|d| Path::new(d).join(bin).exists())
}

/// Stops the cluster when dropped.
struct Cluster(PathBuf);

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new(root().join("examples/slurm/local-cluster.sh"))
            .arg("stop")
            .arg(&self.0)
            .status();
    }
}

#[test]
fn a_slurm_job_array_bakes_the_same_pvs_as_one_machine() {
    let ci = std::env::var("CI").is_ok_and(|v| v == "true");
    let missing = || -> Vec<&str> {
        ["munged", "slurmctld", "slurmd", "sbatch"]
            .into_iter()
            .filter(|b| !found(b))
            .collect()
    };
    if ci && !missing().is_empty() {
        // CI installs Slurm from Debian's packages here.
        let apt = |args: &[&str]| {
            Command::new("apt-get")
                .args(args)
                .env("DEBIAN_FRONTEND", "noninteractive")
                .output()
                .map(|o| {
                    (
                        o.status.success(),
                        String::from_utf8_lossy(&o.stderr).to_string(),
                    )
                })
                .unwrap_or_else(|e| (false, e.to_string()))
        };
        let (ok, err) = apt(&["update", "-qq"]);
        assert!(ok, "apt-get update failed: {err}");
        let (ok, err) = apt(&["install", "-y", "-qq", "slurm-wlm", "munge"]);
        assert!(ok, "apt-get install slurm-wlm munge failed: {err}");
    }
    let missing = missing();
    if !missing.is_empty() {
        assert!(
            !ci,
            "Slurm is not installed ({missing:?} missing) even after apt-get install slurm-wlm munge"
        );
        eprintln!(
            "skipping: Slurm is not installed ({missing:?}; apt-get install slurm-wlm munge)"
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let cluster_dir = dir.path().join("cluster");
    let start = Command::new(root().join("examples/slurm/local-cluster.sh"))
        .arg("start")
        .arg(&cluster_dir)
        .env(
            "PATH",
            format!("{}:/usr/sbin", std::env::var("PATH").unwrap_or_default()),
        )
        .output()
        .unwrap();
    let _cluster = Cluster(cluster_dir.clone());
    let stdout = String::from_utf8_lossy(&start.stdout);
    let stderr = String::from_utf8_lossy(&start.stderr);
    if !start.status.success() {
        assert!(!ci, "the local cluster did not start:\n{stdout}\n{stderr}");
        eprintln!("skipping: the local Slurm cluster did not start (not root?):\n{stderr}");
        return;
    }
    let conf = cluster_dir.join("slurm.conf");
    assert!(stdout.contains("SLURM_CONF="), "{stdout}");

    // 48 small cells on the demo city's streets and roofs, three shards.
    let cells: Vec<String> = (0..8)
        .flat_map(|i| {
            (0..6).map(move |j| {
                let (x, z) = (-80 + 20 * i, -60 + 20 * j);
                format!(
                    "{{\"min\": [{x}, 1, {z}], \"max\": [{}, 3, {}]}}",
                    x + 4,
                    z + 4
                )
            })
        })
        .collect();
    let cells_path = dir.path().join("cells.json");
    std::fs::write(
        &cells_path,
        format!("{{\"cells\": [{}]}}", cells.join(", ")),
    )
    .unwrap();
    let scene = root().join("data/demo_city.obj");
    let merged = dir.path().join("merged.pvs");
    let t = Instant::now();
    let submit = Command::new(root().join("examples/slurm/submit.sh"))
        .arg(&scene)
        .arg(&cells_path)
        .arg("3")
        .arg(&merged)
        .env("SLURM_CONF", &conf)
        .env("UMBRASWEEP", env!("CARGO_BIN_EXE_umbrasweep"))
        .output()
        .unwrap();
    assert!(
        submit.status.success(),
        "submit.sh failed:\n{}",
        String::from_utf8_lossy(&submit.stderr)
    );
    let logs = || {
        let mut s = String::new();
        for f in ["bake-0.out", "bake-1.out", "bake-2.out", "merge.out"] {
            let p = dir.path().join("merged.pvs.shards/log").join(f);
            s += &format!(
                "--- {f}\n{}\n",
                std::fs::read_to_string(p).unwrap_or_default()
            );
        }
        s += &std::fs::read_to_string(cluster_dir.join("log/slurmctld.log")).unwrap_or_default();
        s
    };
    while !merged.exists() {
        assert!(
            t.elapsed() < Duration::from_secs(600),
            "no merged output after 10 minutes:\n{}",
            logs()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let wall = t.elapsed();
    for i in 0..3 {
        assert!(
            dir.path()
                .join(format!("merged.pvs.shards/shard-{i}.json"))
                .exists(),
            "shard {i} missing:\n{}",
            logs()
        );
    }
    let single = dir.path().join("single.pvs");
    let r = Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
        .arg("bake")
        .arg(&scene)
        .arg("--cells")
        .arg(&cells_path)
        .arg("-o")
        .arg(&single)
        .args(["--reproducible", "-q"])
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(
        std::fs::read(&merged).unwrap(),
        std::fs::read(&single).unwrap(),
        "the Slurm bake differs from the single-machine bake:\n{}",
        logs()
    );
    eprintln!(
        "slurm: 3-task array and merge in {:.1} s",
        wall.as_secs_f64()
    );
}
