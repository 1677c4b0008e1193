//! The cluster files in docker/ (a Kubernetes Indexed Job with its merge Job, a SLURM job
//! array) parse, split the campaign the way `eval --shard` counts (the pod or task index K of
//! N shares, N the same everywhere), and pass `sim-bridge eval` only flags it has. No cluster
//! runs here; the YAML is read with Python's yaml (a dependency of ray, in tests/requirements.txt).

use std::path::{Path, PathBuf};
use std::process::Command;

use ssrdrive_tests::{binary, python_skipped, yaml_as_json};

fn docker_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../docker")
}

/// Every `--flag` of `sim-bridge eval --help`.
fn eval_flags() -> Vec<String> {
    let help = Command::new(binary("sim-bridge"))
        .args(["eval", "--help"])
        .output()
        .unwrap();
    String::from_utf8_lossy(&help.stdout)
        .split_whitespace()
        .filter(|w| w.starts_with("--"))
        .map(|w| w.trim_end_matches(',').to_string())
        .collect()
}

/// The flag names (`--name`) among `args`.
fn flags<'a>(args: impl IntoIterator<Item = &'a str>) -> Vec<&'a str> {
    args.into_iter()
        .filter(|a| a.starts_with("--"))
        .map(|a| a.split('=').next().unwrap())
        .collect()
}

#[test]
fn the_indexed_job_splits_by_the_completion_index_and_the_merge_reads_every_part() {
    if python_skipped("the manifest check") {
        return;
    }
    let job = yaml_as_json(&docker_dir().join("k8s/eval-indexed-job.yaml"));
    assert_eq!(job["kind"], "Job");
    assert_eq!(job["spec"]["completionMode"], "Indexed");
    let shares = job["spec"]["completions"].as_u64().unwrap();
    let container = &job["spec"]["template"]["spec"]["containers"][0];
    let args: Vec<&str> = container["args"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap())
        .collect();
    assert_eq!(args[0], "eval");
    assert!(
        args.contains(&format!("--shard=$(JOB_COMPLETION_INDEX)/{shares}").as_str()),
        "{args:?}"
    );
    let part = format!("part-$(JOB_COMPLETION_INDEX)-of-{shares}.json");
    assert!(
        args.iter()
            .any(|a| a.starts_with("--out=") && a.ends_with(&part)),
        "{args:?}"
    );
    assert!(args.contains(&"--resume"), "a restarted pod keeps its runs");
    let known = eval_flags();
    for flag in flags(args[1..].iter().copied()) {
        assert!(known.iter().any(|k| k == flag), "eval has no {flag}");
    }
    let merge = yaml_as_json(&docker_dir().join("k8s/merge-job.yaml"));
    let script = merge["spec"]["template"]["spec"]["containers"][0]["args"][0]
        .as_str()
        .unwrap();
    assert!(
        script.contains(&format!("part-*-of-{shares}.json"))
            && script.contains("sim-bridge results merge"),
        "{script}"
    );
}

#[test]
fn the_slurm_array_has_a_task_per_share() {
    let script_path = docker_dir().join("slurm/eval-array.sh");
    let syntax = Command::new("bash")
        .arg("-n")
        .arg(&script_path)
        .status()
        .unwrap();
    assert!(syntax.success(), "bash -n {}", script_path.display());
    let script = std::fs::read_to_string(&script_path).unwrap();
    let value = |prefix: &str| {
        script
            .lines()
            .find_map(|l| l.strip_prefix(prefix))
            .unwrap_or_else(|| panic!("no {prefix}"))
            .trim()
            .to_string()
    };
    let shares: u64 = value("SHARES=").parse().unwrap();
    assert_eq!(value("#SBATCH --array="), format!("0-{}", shares - 1));
    assert!(script.contains("--shard \"$SLURM_ARRAY_TASK_ID/$SHARES\""));
    assert!(
        script.contains("--resume"),
        "a requeued task keeps its runs"
    );
    let command: String = script
        .split("exec \"$SIM_BRIDGE\" eval")
        .nth(1)
        .expect("the eval line")
        .replace("\\\n", " ");
    let known = eval_flags();
    for flag in flags(command.split_whitespace()) {
        assert!(known.iter().any(|k| k == flag), "eval has no {flag}");
    }
}
