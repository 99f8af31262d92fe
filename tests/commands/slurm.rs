//! The documented Slurm example (docs/src/commands/batch.md) on a real cluster (issue 53): Debian's
//! Slurm and MUNGE, one node on 127.0.0.1, configured and started under a temporary folder (no
//! systemd, no cgroups: `proctrack/linuxproc`, `task/none`, accounting off) and stopped by PID
//! at the end, whatever happens. The example's array job, paths substituted, converts a dozen
//! takes (one damaged) into one output folder: every good take converted exactly once, its BVH
//! and GLB byte-identical to `convert`'s, the damaged one reported and its array task failed, and
//! a re-submission converting nothing. The Kubernetes example's environment is checked without a
//! cluster: every index of its Indexed Job, with the variables the example sets, is one shard of a
//! partition.

use crate::common;
use imubake::ledger::{Ledger, LedgerEntry, Status, ledger_dir};
use std::collections::BTreeMap;
use std::fs;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const TOOLS: [&str; 7] = [
    "/usr/sbin/munged",
    "/usr/sbin/slurmctld",
    "/usr/sbin/slurmd",
    "/usr/bin/sbatch",
    "/usr/bin/squeue",
    "/usr/bin/scontrol",
    "/usr/bin/sinfo",
];

/// A one-node Slurm cluster under a temporary folder; its daemons are stopped when it drops.
struct Cluster {
    dir: tempfile::TempDir,
}

impl Cluster {
    fn conf(&self) -> PathBuf {
        self.dir.path().join("slurm.conf")
    }

    fn path(&self, rel: &str) -> PathBuf {
        self.dir.path().join(rel)
    }

    /// A Slurm command of this cluster.
    fn command(&self, program: &str) -> Command {
        let mut cmd = Command::new(program);
        cmd.env("SLURM_CONF", self.conf());
        cmd
    }

    fn start() -> Option<Cluster> {
        for tool in TOOLS {
            if !Path::new(tool).is_file() {
                return common::missing(&format!("Slurm's {tool} (run scripts/test.sh)"));
            }
        }
        // Made before any daemon starts, so that a failure below still stops those started.
        let cluster = Cluster {
            dir: tempfile::Builder::new().prefix("slurm").tempdir().unwrap(),
        };
        for sub in ["munge", "state", "spool", "log"] {
            fs::create_dir_all(cluster.path(sub)).unwrap();
        }
        fs::set_permissions(cluster.path("munge"), fs::Permissions::from_mode(0o700)).unwrap();
        let mut key = vec![0u8; 1024];
        std::io::Read::read_exact(&mut fs::File::open("/dev/urandom").unwrap(), &mut key).unwrap();
        let key_path = cluster.path("munge/munge.key");
        fs::write(&key_path, &key).unwrap();
        fs::set_permissions(&key_path, fs::Permissions::from_mode(0o600)).unwrap();
        let port = || {
            std::net::TcpListener::bind("127.0.0.1:0")
                .unwrap()
                .local_addr()
                .unwrap()
                .port()
        };
        let hostname = fs::read_to_string("/proc/sys/kernel/hostname").unwrap();
        // The example asks 2 CPUs per task, so the node runs its tasks one after another;
        // without a scheduling delay each waits about 1 s for the next pass instead of 3.
        let d = cluster.dir.path().display();
        let conf = format!(
            "ClusterName=imubaketest\n\
             SlurmctldHost=localhost(127.0.0.1)\n\
             SlurmctldPort={ctld}\nSlurmdPort={slurmd}\n\
             SlurmUser=root\nSlurmdUser=root\n\
             AuthType=auth/munge\nCredType=cred/munge\nAuthInfo=socket={d}/munge/munge.socket\n\
             ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\n\
             JobAcctGatherType=jobacct_gather/none\nAccountingStorageType=accounting_storage/none\n\
             SchedulerType=sched/backfill\nSelectType=select/cons_tres\nSelectTypeParameters=CR_Core\n\
             SchedulerParameters=batch_sched_delay=0,sched_min_interval=0\n\
             ReturnToService=2\nMpiDefault=none\n\
             StateSaveLocation={d}/state\nSlurmdSpoolDir={d}/spool\n\
             SlurmctldPidFile={d}/slurmctld.pid\nSlurmdPidFile={d}/slurmd.pid\n\
             SlurmctldLogFile={d}/log/slurmctld.log\nSlurmdLogFile={d}/log/slurmd.log\n\
             NodeName=imubake1 NodeAddr=127.0.0.1 NodeHostname={host} CPUs=2 State=UNKNOWN\n\
             PartitionName=test Nodes=ALL Default=YES MaxTime=INFINITE State=UP\n",
            ctld = port(),
            slurmd = port(),
            host = hostname.trim(),
        );
        fs::write(cluster.conf(), conf).unwrap();
        let started = |cmd: &mut Command, what: &str| {
            let out = cmd.output().unwrap_or_else(|e| panic!("{what}: {e}"));
            assert!(
                out.status.success(),
                "{what} did not start: {}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
        };
        // Each daemon forks into the background and writes its PID file.
        started(
            Command::new("/usr/sbin/munged")
                .arg("--force")
                .arg(format!("--socket={d}/munge/munge.socket"))
                .arg(format!("--key-file={d}/munge/munge.key"))
                .arg(format!("--pid-file={d}/munge/munged.pid"))
                .arg(format!("--log-file={d}/munge/munged.log"))
                .arg(format!("--seed-file={d}/munge/seed")),
            "munged",
        );
        started(
            cluster.command("/usr/sbin/slurmctld").arg("-i"),
            "slurmctld",
        );
        started(
            cluster.command("/usr/sbin/slurmd").args(["-N", "imubake1"]),
            "slurmd",
        );
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            let out = cluster
                .command("/usr/bin/sinfo")
                .args(["-h", "-o", "%T"])
                .output()
                .unwrap();
            if String::from_utf8_lossy(&out.stdout).trim() == "idle" {
                break;
            }
            assert!(
                Instant::now() < deadline,
                "the node is not idle after 30 s: {}\n{}",
                String::from_utf8_lossy(&out.stdout),
                fs::read_to_string(cluster.path("log/slurmctld.log")).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        Some(cluster)
    }

    /// Submits `script` from `cwd` and waits for every task of its array; the job id.
    fn run(&self, script: &Path, cwd: &Path) -> String {
        let out = self
            .command("/usr/bin/sbatch")
            .arg("--parsable")
            .arg(script)
            .current_dir(cwd)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "sbatch: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let id = String::from_utf8_lossy(&out.stdout)
            .trim()
            .split(';')
            .next()
            .unwrap()
            .to_string();
        let deadline = Instant::now() + Duration::from_secs(120);
        loop {
            let out = self
                .command("/usr/bin/squeue")
                .args(["-h", "-j", &id])
                .output()
                .unwrap();
            if out.status.success() && out.stdout.iter().all(u8::is_ascii_whitespace) {
                return id;
            }
            assert!(
                Instant::now() < deadline,
                "job {id} still queued after 120 s"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// Each array task of job `id`: its index → (state, exit code), from `scontrol` (which keeps
    /// finished jobs for a while; `sacct` would need slurmdbd).
    fn tasks(&self, id: &str) -> BTreeMap<usize, (String, String)> {
        let out = self
            .command("/usr/bin/scontrol")
            .args(["show", "job", "-o", id])
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        text.lines()
            .map(|line| {
                let field = |key: &str| {
                    line.split_whitespace()
                        .find_map(|f| f.strip_prefix(key))
                        .unwrap_or_else(|| panic!("no {key} in {line}"))
                        .to_string()
                };
                (
                    field("ArrayTaskId=").parse().unwrap(),
                    (field("JobState="), field("ExitCode=")),
                )
            })
            .collect()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for pid_file in ["slurmd.pid", "slurmctld.pid", "munge/munged.pid"] {
            let Ok(text) = fs::read_to_string(self.path(pid_file)) else {
                continue;
            };
            let Ok(pid) = text.trim().parse::<i32>() else {
                continue;
            };
            unsafe { libc::kill(pid, libc::SIGTERM) };
            let deadline = Instant::now() + Duration::from_secs(5);
            while Path::new(&format!("/proc/{pid}")).exists() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(50));
            }
            if Path::new(&format!("/proc/{pid}")).exists() {
                unsafe { libc::kill(pid, libc::SIGKILL) };
            }
        }
    }
}

/// The code block of docs/src/commands/batch.md whose first lines are `first` (its language
/// tag `lang`).
fn documented(lang: &str, first: &str) -> String {
    let page = fs::read_to_string(common::repo_file("docs/src/commands/batch.md")).unwrap();
    let start = page
        .find(&format!("```{lang}\n{first}"))
        .unwrap_or_else(|| panic!("batch.md has no {lang} block starting {first:?}"))
        + lang.len()
        + 4;
    let end = start + page[start..].find("```").unwrap();
    page[start..end].to_string()
}

/// Every line of every ledger file under `out`.
fn ledger_lines(out: &Path) -> Vec<LedgerEntry> {
    let mut lines = Vec::new();
    for e in fs::read_dir(ledger_dir(out)).unwrap() {
        let text = fs::read_to_string(e.unwrap().path()).unwrap();
        for line in text.lines() {
            lines.push(serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}")));
        }
    }
    lines
}

#[test]
fn the_documented_slurm_array_converts_each_take_once() {
    let Some(cluster) = Cluster::start() else {
        return;
    };
    let work = tempfile::tempdir().unwrap();
    let (takes, out) = (work.path().join("captures"), work.path().join("out"));
    fs::create_dir_all(&takes).unwrap();
    // Eleven walks of different lengths, and one damaged file.
    let walk = fs::read_to_string(common::repo_file("samples/walk.csv")).unwrap();
    let lines: Vec<&str> = walk.lines().collect();
    let mut good = Vec::new();
    for k in 0..11 {
        let name = format!("walk_{k:02}.csv");
        let kept = lines.len() - 160 * k;
        fs::write(takes.join(&name), lines[..kept].join("\n") + "\n").unwrap();
        good.push(name);
    }
    fs::write(
        takes.join("walk_05_damaged.csv"),
        "sensor,t\nnot a capture\n",
    )
    .unwrap();
    let config = work.path().join("imubake.yaml");
    let mapping = common::repo_file("mappings/paper000_16imu_mixamo.json");
    fs::write(&config, format!("mapping: {}\n", mapping.display())).unwrap();

    // The documented script, its paths substituted.
    let mut script = documented("sh", "#!/bin/bash\n# Slurm");
    for (from, to) in [
        ("/data/captures", takes.display().to_string()),
        ("/data/out", out.display().to_string()),
        ("/data/imubake.yaml", config.display().to_string()),
        (
            "imubake batch",
            format!("{} batch", common::imubake_bin().display()),
        ),
    ] {
        assert!(script.contains(from), "the example names {from}: {script}");
        script = script.replace(from, &to);
    }
    let count: usize = script
        .lines()
        .find_map(|l| l.strip_prefix("#SBATCH --array=0-"))
        .expect("the example's array is 0-N")
        .trim()
        .parse::<usize>()
        .unwrap()
        + 1;
    let script_path = work.path().join("imubake.sbatch");
    fs::write(&script_path, &script).unwrap();

    // The damaged take's shard: its place in relative-path order, modulo the array's size.
    let mut all: Vec<String> = good.clone();
    all.push("walk_05_damaged.csv".into());
    all.sort();
    let bad_shard = all.iter().position(|t| t == "walk_05_damaged.csv").unwrap() % count;

    let expect_tasks = |id: &str| {
        let tasks = cluster.tasks(id);
        assert_eq!(tasks.len(), count, "{tasks:?}");
        for (i, (state, code)) in &tasks {
            if *i == bad_shard {
                assert_eq!(
                    (state.as_str(), code.as_str()),
                    ("FAILED", "1:0"),
                    "task {i}"
                );
            } else {
                assert_eq!(
                    (state.as_str(), code.as_str()),
                    ("COMPLETED", "0:0"),
                    "task {i}"
                );
            }
        }
    };
    let started = Instant::now();
    let id = cluster.run(&script_path, work.path());
    eprintln!(
        "the array of {count} ran in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    expect_tasks(&id);

    // Every good take exactly once, as `convert` makes it; the damaged one failed.
    let lines = ledger_lines(&out);
    for name in &good {
        let converted = lines
            .iter()
            .filter(|e| e.source == *name && e.status == Status::Converted)
            .count();
        assert_eq!(converted, 1, "{name}: {converted} conversions");
    }
    assert!(
        lines
            .iter()
            .any(|e| e.source == "walk_05_damaged.csv" && e.status == Status::Failed)
    );
    assert!(out.join("walk_05_damaged.error.json").is_file());
    let direct = work.path().join("direct");
    for name in &good {
        let run = Command::new(common::imubake_bin())
            .arg("convert")
            .arg(takes.join(name))
            .arg("--config")
            .arg(&config)
            .arg("--out")
            .arg(&direct)
            .output()
            .unwrap();
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let stem = name.trim_end_matches(".csv");
        for ext in ["bvh", "glb"] {
            let file = format!("{stem}.{ext}");
            assert!(
                fs::read(out.join(&file)).unwrap() == fs::read(direct.join(&file)).unwrap(),
                "{file} differs from convert's"
            );
        }
    }

    // Submitted again: nothing converts; the damaged take's task fails again.
    let id = cluster.run(&script_path, work.path());
    expect_tasks(&id);
    let again = ledger_lines(&out);
    assert_eq!(
        again
            .iter()
            .filter(|e| e.status == Status::Converted)
            .count(),
        good.len(),
        "a re-submission converted something"
    );
    let ledger = Ledger::load(&out).unwrap();
    assert_eq!(ledger.len(), good.len() + 1);
    assert_eq!(ledger.skipped_lines(), 0);
    eprintln!(
        "two submissions and the checks in {:.1} s",
        started.elapsed().as_secs_f64()
    );
}

/// The Kubernetes example's Indexed Job: each completion index, with the environment the
/// example's pod gets (`JOB_COMPLETION_INDEX` from Kubernetes, `IMUBAKE_SHARD_COUNT` from the
/// example), lists one shard, and the shards together list every take once.
#[test]
fn the_documented_kubernetes_job_shards_by_its_index() {
    let yaml = documented("yaml", "# Kubernetes");
    let job: serde_yaml::Value = serde_yaml::from_str(&yaml).unwrap();
    let spec = &job["spec"];
    assert_eq!(spec["completionMode"].as_str(), Some("Indexed"));
    let completions = spec["completions"].as_u64().unwrap() as usize;
    let container = &spec["template"]["spec"]["containers"][0];
    let env: Vec<(String, String)> = container["env"]
        .as_sequence()
        .unwrap()
        .iter()
        .map(|v| {
            (
                v["name"].as_str().unwrap().to_string(),
                v["value"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    let args: Vec<String> = container["args"]
        .as_sequence()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap().to_string())
        .collect();
    assert_eq!(args[0], "batch");

    let work = tempfile::tempdir().unwrap();
    let captures = work.path().join("captures");
    fs::create_dir_all(&captures).unwrap();
    let takes: Vec<String> = (0..20).map(|n| format!("take_{n:02}.csv")).collect();
    for t in &takes {
        fs::write(captures.join(t), "x\n").unwrap();
    }
    let config = work.path().join("imubake.yaml");
    fs::write(&config, "formats: [bvh]\n").unwrap();
    let mut listed = Vec::new();
    for index in 0..completions {
        let mut cmd = Command::new(common::imubake_bin());
        // The example's arguments, the library and output paths substituted, listing only.
        for a in &args {
            cmd.arg(
                a.replace("/data/captures", &captures.display().to_string())
                    .replace("/data/out", &work.path().join("out").display().to_string())
                    .replace("/data/imubake.yaml", &config.display().to_string()),
            );
        }
        cmd.arg("--list");
        for v in [
            "SLURM_ARRAY_TASK_ID",
            "SLURM_ARRAY_TASK_COUNT",
            "SLURM_ARRAY_TASK_MIN",
            "SLURM_ARRAY_TASK_STEP",
            "IMUBAKE_SHARD_COUNT",
        ] {
            cmd.env_remove(v);
        }
        cmd.env("JOB_COMPLETION_INDEX", index.to_string());
        for (k, v) in &env {
            cmd.env(k, v);
        }
        let out = cmd.output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let shard: Vec<String> = String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(str::to_string)
            .collect();
        // Index i lists the takes at i, i + completions, … in path order.
        let expected: Vec<String> = takes
            .iter()
            .skip(index)
            .step_by(completions)
            .cloned()
            .collect();
        assert_eq!(shard, expected, "index {index}");
        listed.extend(shard);
    }
    listed.sort();
    assert_eq!(listed, takes);
}
