//! `stagelight slurm`: writes the Slurm batch scripts that run one render or reference as a
//! job array of shards plus a merge job that waits for them, and a `submit.sh` that submits
//! both (`sbatch --parsable`, then `--dependency=afterok:ARRAY`).
//!
//! Each array task runs the command with `--shard $SLURM_ARRAY_TASK_ID/N` and its own
//! output under `DIR/parts/`. Slurm sends SIGINT to the task's batch shell some seconds
//! before its time limit (`--signal=B:INT@S`); the shell passes it on, the render stops after
//! the passes in flight and keeps them (a reference in its checkpoint), and a reference's
//! task requeues itself (`scontrol requeue`): the next run resumes from the checkpoint. A
//! `scancel` (SIGTERM) stops it the same way but is not requeued. The merge job then adds the
//! parts into the command's own `-o` output.

use anyhow::{Context, Result, bail};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What `stagelight slurm` was asked for.
#[derive(Clone, Debug)]
pub struct SlurmOptions {
    /// Shards (array tasks).
    pub shards: u64,
    /// Folder of the scripts, the parts and the logs.
    pub dir: PathBuf,
    /// The stagelight command to shard: `render ...` or `reference ...`, with `-o OUT.exr`.
    pub command: Vec<String>,
    /// The stagelight binary the jobs run (default: this one).
    pub binary: PathBuf,
    /// The folder the jobs run in (relative paths of the command are relative to it).
    pub workdir: PathBuf,
    /// `#SBATCH --partition`, `--time` (of each shard), `--cpus-per-task`.
    pub partition: Option<String>,
    pub time_limit: Option<String>,
    pub cpus_per_task: Option<u32>,
    /// Seconds before a shard's time limit that Slurm asks it to stop (`--signal=B:INT@S`).
    pub signal_seconds: u32,
    /// Job name prefix.
    pub name: String,
}

/// The scripts, as written.
#[derive(Clone, Debug, PartialEq)]
pub struct SlurmScripts {
    pub shards: String,
    pub merge: String,
    pub submit: String,
}

/// The value of `-o`/`--output` in a command line, and where it is.
fn output_of(command: &[String]) -> Option<(usize, String)> {
    let mut i = 0;
    while i < command.len() {
        let arg = &command[i];
        if (arg == "-o" || arg == "--output") && i + 1 < command.len() {
            return Some((i, command[i + 1].clone()));
        }
        if let Some(v) = arg.strip_prefix("--output=") {
            return Some((i, v.to_string()));
        }
        i += 1;
    }
    None
}

/// The command line without its `-o OUT` (and with `--quiet`).
fn without_output(command: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < command.len() {
        let arg = &command[i];
        if arg == "-o" || arg == "--output" {
            i += 2;
            continue;
        }
        if !arg.starts_with("--output=") && arg != "--quiet" {
            out.push(arg.clone());
        }
        i += 1;
    }
    out.push("--quiet".into());
    out
}

/// Quotes a word for a POSIX shell: as it is when it is plainly safe, else in single quotes.
pub fn shell_quote(word: &str) -> String {
    let safe = !word.is_empty()
        && word
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"-_./=:,+@%".contains(&b));
    if safe {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', r"'\''"))
    }
}

fn words(list: &[String]) -> String {
    list.iter()
        .map(|w| shell_quote(w))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Checks the command to shard: `render` or `reference`, with `-o OUT.exr`, no shard or time
/// budget of its own. Returns the merged output.
pub fn check_command(command: &[String]) -> Result<String> {
    match command.first().map(String::as_str) {
        Some("render" | "reference") => {}
        Some(other) => bail!(
            "stagelight slurm shards `render` or `reference`, not `{}`",
            crate::scene::clip(other, 60)
        ),
        None => bail!("stagelight slurm needs the command to shard after `--`"),
    }
    for word in command {
        for refused in ["--shard", "--pass-range", "--time"] {
            if word == refused || word.starts_with(&format!("{refused}=")) {
                bail!(
                    "{refused}: the shards' passes are chosen by stagelight slurm (give --spp \
                     and --shards)"
                );
            }
        }
    }
    let (_, output) = output_of(command)
        .context("the command needs -o OUT.exr: the merged image is written there")?;
    if !output.to_ascii_lowercase().ends_with(".exr") {
        bail!("{output}: the output must be an .exr file");
    }
    Ok(output)
}

/// The scripts for `o` (nothing written).
pub fn scripts(o: &SlurmOptions) -> Result<SlurmScripts> {
    if o.shards == 0 {
        bail!("--shards must be at least 1");
    }
    let output = check_command(&o.command)?;
    let is_reference = o.command[0] == "reference";
    let dir = absolute(&o.dir, &o.workdir);
    let parts = dir.join("parts");
    let logs = dir.join("logs");
    let part = |task: &str| parts.join(format!("part-{task}.exr")).display().to_string();
    let binary = shell_quote(&o.binary.display().to_string());
    let n = o.shards;
    let mut common = String::new();
    writeln!(common, "#SBATCH --chdir={}", o.workdir.display())?;
    if let Some(p) = &o.partition {
        writeln!(common, "#SBATCH --partition={p}")?;
    }

    let mut shards = String::new();
    writeln!(shards, "#!/bin/bash")?;
    writeln!(
        shards,
        "# Written by `stagelight slurm`: shard I of {n} of `stagelight {}`.",
        words(&o.command)
    )?;
    writeln!(shards, "#SBATCH --job-name={}-shards", o.name)?;
    writeln!(shards, "#SBATCH --array=1-{n}")?;
    shards += &common;
    writeln!(shards, "#SBATCH --output={}/shard-%a.out", logs.display())?;
    if let Some(t) = &o.time_limit {
        writeln!(shards, "#SBATCH --time={t}")?;
    }
    if let Some(c) = o.cpus_per_task {
        writeln!(shards, "#SBATCH --cpus-per-task={c}")?;
    }
    writeln!(
        shards,
        "# SIGINT to this shell {} s before the time limit: the shard keeps its finished passes.",
        o.signal_seconds
    )?;
    writeln!(shards, "#SBATCH --signal=B:INT@{}", o.signal_seconds)?;
    if is_reference {
        // A requeued shard's run adds to its log rather than replacing it.
        writeln!(shards, "#SBATCH --requeue")?;
        writeln!(shards, "#SBATCH --open-mode=append")?;
    }
    writeln!(shards, "set -u")?;
    writeln!(
        shards,
        "task=\"${{SLURM_ARRAY_TASK_ID:?run me with sbatch}}\""
    )?;
    writeln!(
        shards,
        "part={}/part-\"${{task}}\".exr",
        shell_quote(&parts.display().to_string())
    )?;
    writeln!(
        shards,
        "mkdir -p {}",
        shell_quote(&parts.display().to_string())
    )?;
    let threads = match o.cpus_per_task {
        Some(c) if !o.command.iter().any(|w| w == "--threads") => {
            format!(" --threads \"${{SLURM_CPUS_PER_TASK:-{c}}}\"")
        }
        _ => String::new(),
    };
    writeln!(
        shards,
        "{binary} {} --shard \"${{task}}/{n}\" -o \"$part\"{threads} &",
        words(&without_output(&o.command))
    )?;
    writeln!(shards, "pid=$!")?;
    writeln!(shards, "reason=")?;
    writeln!(
        shards,
        "# Slurm signals this shell (B:), not the render: pass the signal on."
    )?;
    writeln!(
        shards,
        "trap 'reason=limit; kill -INT \"$pid\" 2>/dev/null' INT"
    )?;
    writeln!(
        shards,
        "trap 'reason=cancel; kill -TERM \"$pid\" 2>/dev/null' TERM HUP"
    )?;
    writeln!(shards, "wait \"$pid\"; status=$?")?;
    writeln!(
        shards,
        "while kill -0 \"$pid\" 2>/dev/null; do wait \"$pid\"; status=$?; done"
    )?;
    writeln!(shards, "echo \"shard ${{task}}/{n}: exit $status\"")?;
    if is_reference {
        writeln!(
            shards,
            "# Stopped before the time limit: requeue; the next run resumes from the checkpoint."
        )?;
        writeln!(
            shards,
            "if [ \"$status\" -eq 130 ] && [ \"$reason\" = limit ]; then"
        )?;
        writeln!(
            shards,
            "    scontrol requeue \"${{SLURM_ARRAY_JOB_ID}}_${{task}}\""
        )?;
        writeln!(shards, "fi")?;
    }
    writeln!(shards, "exit \"$status\"")?;

    let mut merge = String::new();
    writeln!(merge, "#!/bin/bash")?;
    writeln!(
        merge,
        "# Written by `stagelight slurm`: adds the {n} shards into {output}; submit.sh starts it \
         once every shard has succeeded."
    )?;
    writeln!(merge, "#SBATCH --job-name={}-merge", o.name)?;
    merge += &common;
    writeln!(merge, "#SBATCH --output={}/merge.out", logs.display())?;
    let all_parts: Vec<String> = (1..=n).map(|i| part(&i.to_string())).collect();
    writeln!(
        merge,
        "exec {binary} merge {} -o {}",
        words(&all_parts),
        shell_quote(&output)
    )?;

    let mut submit = String::new();
    writeln!(submit, "#!/bin/sh")?;
    writeln!(
        submit,
        "# Written by `stagelight slurm`: submits the {n} shards as a job array, then the merge \
         job that waits for all of them."
    )?;
    writeln!(submit, "set -eu")?;
    writeln!(submit, "here=$(cd \"$(dirname \"$0\")\" && pwd)")?;
    writeln!(
        submit,
        "mkdir -p {}",
        shell_quote(&logs.display().to_string())
    )?;
    writeln!(
        submit,
        "array=$(sbatch --parsable \"$here/shards.sbatch\" \"$@\")"
    )?;
    writeln!(submit, "array=${{array%%;*}}")?;
    writeln!(
        submit,
        "merge=$(sbatch --parsable --dependency=afterok:\"$array\" \"$here/merge.sbatch\")"
    )?;
    writeln!(submit, "merge=${{merge%%;*}}")?;
    writeln!(
        submit,
        "echo \"shards: job $array (array 1-{n}); merge: job $merge, after every shard succeeds\""
    )?;
    Ok(SlurmScripts {
        shards,
        merge,
        submit,
    })
}

fn absolute(path: &Path, base: &Path) -> PathBuf {
    if path.is_absolute() {
        path.to_path_buf()
    } else {
        base.join(path)
    }
}

/// Writes the scripts into `o.dir` and says how to submit them. Returns the exit code (0).
pub fn write(o: &SlurmOptions) -> Result<i32> {
    let s = scripts(o)?;
    let dir = absolute(&o.dir, &o.workdir);
    let files = [
        ("shards.sbatch", &s.shards),
        ("merge.sbatch", &s.merge),
        ("submit.sh", &s.submit),
    ];
    for (name, text) in files {
        let path = dir.join(name);
        crate::film::output::write_bytes(&path, text.as_bytes())?;
        set_executable(&path)?;
    }
    super::print_out(&format!(
        "wrote {dir}/shards.sbatch ({n} shards), {dir}/merge.sbatch and {dir}/submit.sh\n\
         submit with: sh {dir}/submit.sh\n",
        dir = dir.display(),
        n = o.shards
    ));
    Ok(0)
}

#[cfg(unix)]
fn set_executable(path: &Path) -> Result<()> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755))
        .with_context(|| format!("{}: cannot make it executable", path.display()))
}

#[cfg(not(unix))]
fn set_executable(_: &Path) -> Result<()> {
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(command: &[&str]) -> SlurmOptions {
        SlurmOptions {
            shards: 4,
            dir: "job".into(),
            command: command.iter().map(|s| s.to_string()).collect(),
            binary: "/opt/stagelight".into(),
            workdir: "/home/me/study".into(),
            partition: Some("short".into()),
            time_limit: Some("1:00:00".into()),
            cpus_per_task: Some(8),
            signal_seconds: 300,
            name: "door".into(),
        }
    }

    #[test]
    fn a_reference_becomes_an_array_of_resumable_shards_and_a_merge() {
        let s = scripts(&options(&[
            "reference",
            "scenes/door ajar.ron",
            "--spp",
            "4096",
            "-o",
            "ref/door.exr",
        ]))
        .unwrap();
        for line in [
            "#SBATCH --array=1-4",
            "#SBATCH --chdir=/home/me/study",
            "#SBATCH --partition=short",
            "#SBATCH --time=1:00:00",
            "#SBATCH --cpus-per-task=8",
            "#SBATCH --signal=B:INT@300",
            "#SBATCH --requeue",
            "#SBATCH --output=/home/me/study/job/logs/shard-%a.out",
            "part=/home/me/study/job/parts/part-\"${task}\".exr",
            "/opt/stagelight reference 'scenes/door ajar.ron' --spp 4096 --quiet --shard \
             \"${task}/4\" -o \"$part\" --threads \"${SLURM_CPUS_PER_TASK:-8}\" &",
            "    scontrol requeue \"${SLURM_ARRAY_JOB_ID}_${task}\"",
        ] {
            assert!(s.shards.lines().any(|l| l == line), "{line}\n{}", s.shards);
        }
        let merge_line = "exec /opt/stagelight merge /home/me/study/job/parts/part-1.exr \
             /home/me/study/job/parts/part-2.exr /home/me/study/job/parts/part-3.exr \
             /home/me/study/job/parts/part-4.exr -o ref/door.exr";
        assert!(s.merge.lines().any(|l| l == merge_line), "{}", s.merge);
        assert!(
            s.submit
                .contains("sbatch --parsable --dependency=afterok:\"$array\""),
            "{}",
            s.submit
        );
    }

    #[test]
    fn a_render_is_not_requeued_and_keeps_its_threads() {
        let s = scripts(&options(&[
            "render",
            "s.ron",
            "--spp",
            "64",
            "--threads",
            "2",
            "--output=out.exr",
        ]))
        .unwrap();
        assert!(!s.shards.contains("requeue"), "{}", s.shards);
        assert!(!s.shards.contains("SLURM_CPUS_PER_TASK"), "{}", s.shards);
        assert!(s.merge.contains("-o out.exr"), "{}", s.merge);
    }

    #[test]
    fn commands_that_cannot_be_sharded_are_refused() {
        for (command, says) in [
            (vec!["compare", "s.ron", "-o", "x"], "not `compare`"),
            (vec!["render", "s.ron", "--spp", "4"], "needs -o"),
            (vec!["render", "s.ron", "-o", "x.png"], "must be an .exr"),
            (
                vec!["render", "s.ron", "--shard", "1/2", "-o", "x.exr"],
                "--shard",
            ),
            (
                vec!["render", "s.ron", "--time", "9", "-o", "x.exr"],
                "--time",
            ),
        ] {
            let e = scripts(&options(&command)).unwrap_err().to_string();
            assert!(e.contains(says), "{command:?}: {e}");
        }
    }

    #[test]
    fn words_are_quoted_for_the_shell() {
        assert_eq!(shell_quote("a/b.ron"), "a/b.ron");
        assert_eq!(shell_quote("a b"), "'a b'");
        assert_eq!(shell_quote("it's"), r"'it'\''s'");
        assert_eq!(shell_quote(""), "''");
        assert_eq!(shell_quote("$HOME"), "'$HOME'");
    }
}
