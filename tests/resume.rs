//! Bakes that survive failure and split across machines: `bake --resume` after a real
//! `kill -9` gives the same bytes as an uninterrupted bake, `bake --shard I/N` + `merge` give
//! the same bytes as one bake whatever the shard and thread counts, and journals or shards of
//! other bakes are refused with clear errors.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
}

fn demo_city() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/demo_city.obj")
}

/// A bake of the demo city over a grid of `nx × nz` cells, reproducible, on the CPU.
fn bake(nx: u32, nz: u32, out: &Path, extra: &[&str], threads: usize) -> Command {
    let mut c = bin();
    c.arg("bake")
        .arg(demo_city())
        .args(["--grid-box", "-80,1,-60,80,3,60", "--grid-size"])
        .arg(format!("{nx},1,{nz}"))
        .arg("-o")
        .arg(out)
        .args(["--backend", "cpu", "--reproducible"])
        .args(extra)
        .env("RAYON_NUM_THREADS", threads.to_string());
    c
}

fn ok(o: &Output) -> String {
    let stderr = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(o.status.success(), "{stderr}");
    stderr
}

fn failed(o: &Output) -> String {
    let stderr = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    stderr
}

/// Starts `bake` and kills it with SIGKILL as soon as `ready()` holds (`what`: what it waits
/// for, in the failure messages).
fn kill_when(mut bake: Command, ready: impl Fn() -> bool, what: &str) {
    let mut child = bake.spawn().unwrap();
    let start = Instant::now();
    while !ready() {
        assert!(
            start.elapsed() < Duration::from_secs(300),
            "the bake never wrote {what}"
        );
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the bake finished ({status}) before {what} could be seen: give it more work");
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
}

/// Starts `bake`, kills it with SIGKILL once its journal holds `n` records, and returns the
/// records the journal holds after the kill.
fn kill_after(bake: Command, journal: &Path, n: usize) -> usize {
    kill_when(
        bake,
        || records(journal) >= n,
        &format!("{n} journal records"),
    );
    records(journal)
}

fn records(journal: &Path) -> usize {
    std::fs::read_to_string(journal)
        .map(|t| t.matches('\n').count().saturating_sub(1))
        .unwrap_or(0)
}

#[test]
fn a_bake_killed_by_kill_9_resumes_to_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let (nx, nz) = (24, 16);
    let whole = dir.path().join("whole.json");
    ok(&bake(nx, nz, &whole, &[], 2).output().unwrap());
    assert!(
        !dir.path().join("whole.json.journal").exists(),
        "a finished bake removes its journal"
    );

    let out = dir.path().join("pvs.json");
    let journal = dir.path().join("pvs.json.journal");
    let at_kill = kill_after(bake(nx, nz, &out, &[], 1), &journal, 5);
    assert!(!out.exists(), "a killed bake leaves no output");
    assert!(at_kill < (nx * nz) as usize, "killed after the last cell");

    ok(&bake(nx, nz, &out, &["--resume"], 2).output().unwrap());
    assert_eq!(
        std::fs::read(&out).unwrap(),
        std::fs::read(&whole).unwrap(),
        "the resumed bake differs from the uninterrupted one"
    );
    assert!(!journal.exists(), "the resumed bake removes its journal");

    // The summary says how many cells came from the journal: all those recorded at the kill.
    let out2 = dir.path().join("pvs2.json");
    let j2 = dir.path().join("pvs2.json.journal");
    let at_kill = kill_after(bake(nx, nz, &out2, &[], 1), &j2, 3);
    let stderr = ok(&bake(nx, nz, &out2, &["--resume"], 2).output().unwrap());
    let line = stderr
        .lines()
        .find(|l| l.starts_with("resumed"))
        .unwrap_or_else(|| panic!("no `resumed` line in:\n{stderr}"));
    let n: usize = line.split_whitespace().nth(1).unwrap().parse().unwrap();
    assert!(
        n >= at_kill,
        "{n} cells resumed, {at_kill} were in the journal: {line}"
    );
    assert_eq!(
        std::fs::read(&out2).unwrap(),
        std::fs::read(&whole).unwrap()
    );
}

#[test]
fn shards_merge_to_the_bytes_of_one_bake_whatever_the_shard_and_thread_counts() {
    let dir = tempfile::tempdir().unwrap();
    let (nx, nz) = (7, 5);
    let whole_json = dir.path().join("whole.json");
    let whole_pvs = dir.path().join("whole.pvs");
    ok(&bake(nx, nz, &whole_json, &[], 2).output().unwrap());
    ok(&bake(nx, nz, &whole_pvs, &[], 1).output().unwrap());
    // Shards as JSON, as .pvs (format version 5), and a mix.
    for (n, threads, kinds) in [
        (1, 2, ["json"; 3]),
        (2, 1, ["pvs"; 3]),
        (3, 2, ["pvs", "json", "pvs"]),
    ] {
        let mut shards = Vec::new();
        // Given to merge in reverse order.
        for i in (0..n).rev() {
            let p = dir.path().join(format!("s{i}of{n}.{}", kinds[i]));
            ok(
                &bake(nx, nz, &p, &["--shard", &format!("{i}/{n}")], threads)
                    .output()
                    .unwrap(),
            );
            shards.push(p);
        }
        for (ext, whole) in [("json", &whole_json), ("pvs", &whole_pvs)] {
            let merged = dir.path().join(format!("merged{n}.{ext}"));
            let r = bin()
                .arg("merge")
                .arg(&merged)
                .args(&shards)
                .output()
                .unwrap();
            ok(&r);
            assert_eq!(
                std::fs::read(&merged).unwrap(),
                std::fs::read(whole).unwrap(),
                "{n} shards, {threads} threads, .{ext}"
            );
        }
    }
}

#[test]
fn merge_refuses_other_bakes_and_missing_or_repeated_shards() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s);
    ok(&bake(4, 3, &p("a0.json"), &["--shard", "0/2"], 2)
        .output()
        .unwrap());
    ok(&bake(4, 3, &p("a1.json"), &["--shard", "1/2"], 2)
        .output()
        .unwrap());
    // Other settings, other shard count.
    ok(&bake(
        4,
        3,
        &p("b1.json"),
        &["--shard", "1/2", "--resolution", "128"],
        2,
    )
    .output()
    .unwrap());
    ok(&bake(4, 3, &p("c1.json"), &["--shard", "1/3"], 2)
        .output()
        .unwrap());
    ok(&bake(4, 3, &p("whole.json"), &[], 2).output().unwrap());
    let merge = |out: &str, shards: &[&str]| {
        bin()
            .arg("merge")
            .arg(p(out))
            .args(shards.iter().map(|s| p(s)))
            .output()
            .unwrap()
    };
    let e = failed(&merge("m.json", &["a0.json", "b1.json"]));
    assert!(e.contains("b1.json") && e.contains("another bake"), "{e}");
    let e = failed(&merge("m.json", &["a0.json", "c1.json"]));
    assert!(e.contains("c1.json") && e.contains("shard count"), "{e}");
    let e = failed(&merge("m.json", &["a1.json"]));
    assert!(e.contains("missing shards: 0/2"), "{e}");
    let e = failed(&merge("m.json", &["a0.json", "a1.json", "a0.json"]));
    assert!(e.contains("given twice: 0/2"), "{e}");
    let e = failed(&merge("m.json", &["a0.json", "whole.json"]));
    assert!(e.contains("whole.json") && e.contains("not a shard"), "{e}");
    ok(&bake(4, 3, &p("whole.pvs"), &[], 2).output().unwrap());
    let e = failed(&merge("m.json", &["a0.json", "whole.pvs"]));
    assert!(e.contains("whole.pvs") && e.contains("not a shard"), "{e}");
    std::fs::write(
        p("bad.json"),
        "{\"format\": \"umbrasweep-shard\", \"version\": 1}",
    )
    .unwrap();
    let e = failed(&merge("m.json", &["a0.json", "bad.json"]));
    assert!(e.contains("bad.json") && e.contains("damaged"), "{e}");
    let e = failed(&merge("m.txt", &["a0.json", "a1.json"]));
    assert!(e.contains("m.txt"), "{e}");
    assert!(!p("m.json").exists(), "no output after a failed merge");
    ok(&merge("m.json", &["a1.json", "a0.json"]));
}

#[test]
fn journals_of_other_bakes_are_refused_and_bad_outputs_fail_before_the_bake() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("pvs.json");
    let journal = dir.path().join("pvs.json.journal");
    // A journal of another bake (another hash of the inputs).
    std::fs::write(
        &journal,
        format!("umbrasweep-journal 1 {}\n", "0".repeat(64)),
    )
    .unwrap();
    let e = failed(&bake(3, 2, &out, &["--resume"], 1).output().unwrap());
    assert!(
        e.contains("pvs.json.journal") && e.contains("another bake"),
        "{e}"
    );
    assert!(!out.exists());
    // Not a journal at all.
    std::fs::write(&journal, "something else\n").unwrap();
    let e = failed(&bake(3, 2, &out, &["--resume"], 1).output().unwrap());
    assert!(e.contains("not an umbrasweep bake journal"), "{e}");
    // Without --resume the journal is replaced, with a warning.
    ok(&bake(3, 2, &out, &[], 1).output().unwrap());
    assert!(out.exists() && !journal.exists());
    // --resume without a journal bakes everything.
    std::fs::remove_file(&out).unwrap();
    ok(&bake(3, 2, &out, &["--resume"], 1).output().unwrap());
    assert!(out.exists());
    // An output folder that does not exist fails before baking, naming the path.
    let e = failed(
        &bake(3, 2, &dir.path().join("no/such/dir/pvs.json"), &[], 1)
            .output()
            .unwrap(),
    );
    assert!(e.contains("no/such/dir"), "{e}");
    let e = failed(&bake(3, 2, &out, &["--shard", "2/2"], 1).output().unwrap());
    assert!(e.contains("expected I/N"), "{e}");
}

/// `bake --resume` inside a cell: the sampler saves its progress to
/// OUTPUT.sampler-<cell> (`--sampling-checkpoint 0`: after every chunk of rectangles); a bake
/// killed with SIGKILL while that file exists resumes from it to the bytes of an uninterrupted
/// bake, says how many rectangles it replayed, and removes the file. A bad value is refused.
#[test]
fn a_sampler_cell_killed_by_kill_9_resumes_from_its_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, cells) = (dir.path().join("forest.obj"), dir.path().join("cells.json"));
    let made = bin()
        .args([
            "gen", "forest", "--preset", "coarse", "--trees", "120", "--leaves", "150",
        ])
        .args(["--seed", "5", "--cells", "1", "--cell-size", "1", "-o"])
        .arg(&scene)
        .arg("--cells-out")
        .arg(&cells)
        .output()
        .unwrap();
    ok(&made);
    let bake = |out: &Path, extra: &[&str]| {
        let mut c = bin();
        c.arg("bake")
            .arg(&scene)
            .arg("--cells")
            .arg(&cells)
            .args([
                "--sampling",
                "--sampling-eps",
                "0.06",
                "--sampling-levels",
                "1",
            ])
            .args([
                "--sampling-resolution",
                "128",
                "--backend",
                "cpu",
                "--reproducible",
            ])
            .arg("-o")
            .arg(out)
            .args(extra)
            .env("RAYON_NUM_THREADS", "2");
        c
    };
    let whole = dir.path().join("whole.json");
    ok(&bake(&whole, &["--sampling-checkpoint", "off"])
        .output()
        .unwrap());

    let out = dir.path().join("pvs.json");
    let checkpoint = || {
        std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.to_string_lossy().contains("pvs.json.sampler-"))
    };
    kill_when(
        bake(&out, &["--sampling-checkpoint", "0"]),
        || checkpoint().is_some(),
        "a sampler checkpoint",
    );
    assert!(!out.exists() && checkpoint().is_some());

    let stderr = ok(&bake(&out, &["--sampling-checkpoint", "0", "--resume"])
        .output()
        .unwrap());
    let line = stderr
        .lines()
        .find(|l| l.contains("sampler rectangles from checkpoints"))
        .unwrap_or_else(|| panic!("no checkpoint line in:\n{stderr}"));
    let n: u64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
    assert!(n > 0, "{line}");
    assert_eq!(
        std::fs::read(&out).unwrap(),
        std::fs::read(&whole).unwrap(),
        "the resumed bake differs from the uninterrupted one"
    );
    assert!(
        checkpoint().is_none(),
        "the finished cell's checkpoint is removed"
    );

    let e = failed(
        &bake(
            &dir.path().join("x.json"),
            &["--sampling-checkpoint", "soon"],
        )
        .output()
        .unwrap(),
    );
    assert!(
        e.contains("--sampling-checkpoint") && e.contains("`off`"),
        "{e}"
    );
}
