//! `stagelight slurm`: writes the Slurm batch scripts that run one render or reference as a
//! job array of shards, or one comparison as a job array of the tasks of a plan, plus a merge
//! job after them, and a `submit.sh` that submits both (`sbatch --parsable`, then
//! `--dependency=afterany:ARRAY`).
//!
//! Each array task runs the command with `--shard $SLURM_ARRAY_TASK_ID/N` and its own
//! output under `DIR/parts/` (a comparison's task: `compare --plan DIR/plan.ron --shard I/N`).
//! Slurm sends SIGINT to the task's batch shell some seconds before its time limit
//! (`--signal=B:INT@S`); the shell passes it on, the render stops after the passes in flight
//! and keeps them (a reference in its checkpoint, a comparison's task in its finished
//! shards), and the task submits the next job of its shard (`--dependency=singleton`: one
//! job of a shard at a time, by name), which resumes where it stopped. No `scontrol
//! requeue`: sites that forbid requeueing run it too, and the next job starts as soon as
//! Slurm schedules it. A `scancel` (SIGTERM) stops a shard the same way but hands nothing on.
//! The merge job starts when every array task has ended, waits (by resubmitting itself)
//! while any shard's next job is still queued or running, then adds the parts into the
//! command's own `-o` output (a comparison: writes its report); a shard that did not finish
//! makes it fail, naming the passes missing.

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
    /// The stagelight command to shard: `render ...` or `reference ...`, with `-o OUT.exr`,
    /// or `compare ...`.
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
    /// Job name prefix (the scene's name and a hash of the job folder: the next job of a
    /// shard waits for the one running by this name).
    pub name: String,
    /// For a comparison: its plan (written as `DIR/plan.ron`, which the tasks read).
    pub plan: Option<crate::compare::shards::PlanFile>,
}

/// The scripts, as written.
#[derive(Clone, Debug, PartialEq)]
pub struct SlurmScripts {
    pub shards: String,
    pub merge: String,
    pub submit: String,
}

/// The plan of a sharded comparison, in the job folder.
pub const PLAN_FILE: &str = "plan.ron";

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

/// Checks the command to shard: `render` or `reference` with `-o OUT.exr` (returned: the
/// merged image), or `compare` (None: its report folder is its own `-o`); no shard or time
/// budget of its own.
pub fn check_command(command: &[String]) -> Result<Option<String>> {
    let refused: &[&str] = match command.first().map(String::as_str) {
        Some("render" | "reference") => &["--shard", "--pass-range", "--time"],
        Some("compare") => &["--shard", "--plan"],
        Some(other) => bail!(
            "stagelight slurm shards `render`, `reference` or `compare`, not `{}`",
            crate::scene::clip(other, 60)
        ),
        None => bail!("stagelight slurm needs the command to shard after `--`"),
    };
    for word in command {
        for refused in refused {
            if word == refused || word.starts_with(&format!("{refused}=")) {
                bail!(
                    "{refused}: the shards' passes are chosen by stagelight slurm (give --spp \
                     and --shards)"
                );
            }
        }
    }
    if command[0] == "compare" {
        return Ok(None);
    }
    let (_, output) = output_of(command)
        .context("the command needs -o OUT.exr: the merged image is written there")?;
    if !output.to_ascii_lowercase().ends_with(".exr") {
        bail!("{output}: the output must be an .exr file");
    }
    Ok(Some(output))
}

/// The job name of a job folder: the scene's name and four hex digits of the folder's path,
/// so that two studies of one scene do not wait for each other's jobs.
pub fn job_name(stem: &str, dir: &Path) -> String {
    // FNV-1a: stable between Rust releases, unlike std's hasher.
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for b in dir.as_os_str().as_encoded_bytes() {
        hash = (hash ^ *b as u64).wrapping_mul(0x0000_0100_0000_01b3);
    }
    let stem: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .take(40)
        .collect();
    format!("{stem}-{:04x}", hash & 0xffff)
}

/// The scripts for `o` (nothing written).
pub fn scripts(o: &SlurmOptions) -> Result<SlurmScripts> {
    if o.shards == 0 {
        bail!("--shards must be at least 1");
    }
    let output = check_command(&o.command)?;
    let is_compare = output.is_none();
    if is_compare != o.plan.is_some() {
        bail!("a comparison is sharded by its plan (and only a comparison)");
    }
    // A reference shard resumes from its checkpoint, a comparison's task from its finished
    // shards; a render shard starts over, so it is not continued.
    let resumable = o.command[0] != "render";
    let dir = absolute(&o.dir, &o.workdir);
    let parts = dir.join("parts");
    let logs = dir.join("logs");
    let plan = shell_quote(&dir.join(PLAN_FILE).display().to_string());
    let binary = shell_quote(&o.binary.display().to_string());
    let shards_script = shell_quote(&dir.join("shards.sbatch").display().to_string());
    let merge_script = shell_quote(&dir.join("merge.sbatch").display().to_string());
    let n = o.shards;
    let name = &o.name;
    let mut common = String::new();
    writeln!(common, "#SBATCH --chdir={}", o.workdir.display())?;
    if let Some(p) = &o.partition {
        writeln!(common, "#SBATCH --partition={p}")?;
    }

    let mut shards = String::new();
    writeln!(shards, "#!/bin/bash")?;
    writeln!(
        shards,
        "# Written by `stagelight slurm`: {} I of {n} of `stagelight {}`.",
        if is_compare { "task" } else { "shard" },
        words(&o.command)
    )?;
    writeln!(shards, "#SBATCH --job-name={name}-shards")?;
    writeln!(shards, "#SBATCH --array=1-{n}")?;
    shards += &common;
    writeln!(shards, "#SBATCH --output={}/shard-%a.out", logs.display())?;
    if resumable {
        // A shard's next job adds to its log rather than replacing it.
        writeln!(shards, "#SBATCH --open-mode=append")?;
    }
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
    writeln!(shards, "set -u")?;
    writeln!(
        shards,
        "task=\"${{SLURM_ARRAY_TASK_ID:?run me with sbatch}}\""
    )?;
    let threads = match o.cpus_per_task {
        Some(c) if !o.command.iter().any(|w| w == "--threads") => {
            format!(" --threads \"${{SLURM_CPUS_PER_TASK:-{c}}}\"")
        }
        _ => String::new(),
    };
    if is_compare {
        writeln!(
            shards,
            "{binary} compare --plan {plan} --shard \"${{task}}/{n}\" --quiet{threads} &"
        )?;
    } else {
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
        writeln!(
            shards,
            "{binary} {} --shard \"${{task}}/{n}\" -o \"$part\"{threads} &",
            words(&without_output(&o.command))
        )?;
    }
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
    if resumable {
        writeln!(
            shards,
            "# Stopped before the time limit: the shard's next job (one at a time, by name) \
             resumes."
        )?;
        writeln!(
            shards,
            "if [ \"$status\" -eq 130 ] && [ \"$reason\" = limit ]; then"
        )?;
        writeln!(
            shards,
            "    if next=$(sbatch --parsable --array=\"$task\" --job-name=\"{name}-shard-$task\" \
             --dependency=\"singleton,afterany:${{SLURM_JOB_ID:?}}\" {shards_script}); then"
        )?;
        writeln!(
            shards,
            "        echo \"shard ${{task}}/{n}: stopped before its time limit; continues in \
             job ${{next%%;*}}\""
        )?;
        writeln!(shards, "        exit 0")?;
        writeln!(shards, "    fi")?;
        writeln!(
            shards,
            "    echo \"shard ${{task}}/{n}: could not submit its next job: submit \
             {shards_script} with --array=$task to go on\" >&2"
        )?;
        writeln!(shards, "fi")?;
    }
    writeln!(shards, "exit \"$status\"")?;

    let mut merge = String::new();
    writeln!(merge, "#!/bin/bash")?;
    match &output {
        Some(output) => writeln!(
            merge,
            "# Written by `stagelight slurm`: adds the {n} shards into {output}; submit.sh \
             starts it once every shard's job has ended."
        )?,
        None => writeln!(
            merge,
            "# Written by `stagelight slurm`: merges the shards of the comparison's {n} tasks \
             and writes its report; submit.sh starts it once every task's job has ended."
        )?,
    }
    writeln!(merge, "#SBATCH --job-name={name}-merge")?;
    merge += &common;
    writeln!(merge, "#SBATCH --output={}/merge.out", logs.display())?;
    writeln!(merge, "#SBATCH --open-mode=append")?;
    writeln!(merge, "set -u")?;
    if resumable {
        writeln!(
            merge,
            "# A shard stopped at its time limit goes on in a job named {name}-shard-I: the \
             merge waits for those."
        )?;
        writeln!(merge, "if command -v squeue >/dev/null; then")?;
        writeln!(
            merge,
            "    left=$(squeue -h --user=\"$(id -un)\" -o '%F %j' 2>/dev/null | awk '$2 ~ \
             /^{name}-shard-[0-9]+$/ {{ print $1 }}' | sort -u | paste -sd: -)"
        )?;
        writeln!(merge, "    if [ -n \"$left\" ]; then")?;
        writeln!(
            merge,
            "        next=$(sbatch --parsable --dependency=\"afterany:$left\" {merge_script}) \
             || exit 1"
        )?;
        writeln!(
            merge,
            "        echo \"merge: shards go on in job(s) $left; the merge follows in job \
             ${{next%%;*}}\""
        )?;
        writeln!(merge, "        exit 0")?;
        writeln!(merge, "    fi")?;
        writeln!(merge, "fi")?;
    }
    match &output {
        Some(output) => {
            let all_parts: Vec<String> = (1..=n)
                .map(|i| parts.join(format!("part-{i}.exr")).display().to_string())
                .collect();
            writeln!(
                merge,
                "exec {binary} merge {} -o {}",
                words(&all_parts),
                shell_quote(output)
            )?;
        }
        None => writeln!(merge, "exec {binary} compare --plan {plan} --quiet")?,
    }

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
        "merge=$(sbatch --parsable --dependency=afterany:\"$array\" \"$here/merge.sbatch\")"
    )?;
    writeln!(submit, "merge=${{merge%%;*}}")?;
    writeln!(
        submit,
        "echo \"shards: job $array (array 1-{n}); merge: job $merge, once every shard has \
         ended\""
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

/// Writes the scripts (and a comparison's plan) into `o.dir` and says how to submit them.
/// Returns the exit code (0).
pub fn write(o: &SlurmOptions) -> Result<i32> {
    let s = scripts(o)?;
    let dir = absolute(&o.dir, &o.workdir);
    if let Some(plan) = &o.plan {
        plan.write(&dir.join(PLAN_FILE))?;
    }
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
    let mut text = match &o.plan {
        Some(plan) => format!(
            "wrote {dir}/{PLAN_FILE} ({}), {dir}/shards.sbatch ({n} tasks), {dir}/merge.sbatch \
             and {dir}/submit.sh\n",
            plan.describe(),
            dir = dir.display(),
            n = o.shards
        ),
        None => format!(
            "wrote {dir}/shards.sbatch ({n} shards), {dir}/merge.sbatch and {dir}/submit.sh\n",
            dir = dir.display(),
            n = o.shards
        ),
    };
    text += &format!("submit with: sh {}/submit.sh\n", dir.display());
    if o.plan.is_some() {
        text += &format!(
            "or, without Slurm: stagelight compare --plan {plan} --shard I/{n} for each I of 1 \
             to {n} (on any machines that see this folder), then stagelight compare --plan \
             {plan} for the report\n",
            plan = dir.join(PLAN_FILE).display(),
            n = o.shards
        );
    }
    super::print_out(&text);
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
            name: "door-1a2b".into(),
            plan: None,
        }
    }

    #[test]
    fn a_reference_becomes_an_array_of_shards_that_go_on_in_their_next_job() {
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
            "#SBATCH --job-name=door-1a2b-shards",
            "#SBATCH --array=1-4",
            "#SBATCH --chdir=/home/me/study",
            "#SBATCH --partition=short",
            "#SBATCH --time=1:00:00",
            "#SBATCH --cpus-per-task=8",
            "#SBATCH --signal=B:INT@300",
            "#SBATCH --open-mode=append",
            "#SBATCH --output=/home/me/study/job/logs/shard-%a.out",
            "part=/home/me/study/job/parts/part-\"${task}\".exr",
            "/opt/stagelight reference 'scenes/door ajar.ron' --spp 4096 --quiet --shard \
             \"${task}/4\" -o \"$part\" --threads \"${SLURM_CPUS_PER_TASK:-8}\" &",
            "    if next=$(sbatch --parsable --array=\"$task\" --job-name=\"door-1a2b-shard-$task\" \
             --dependency=\"singleton,afterany:${SLURM_JOB_ID:?}\" \
             /home/me/study/job/shards.sbatch); then",
        ] {
            assert!(s.shards.lines().any(|l| l == line), "{line}\n{}", s.shards);
        }
        assert!(!s.shards.contains("requeue"), "{}", s.shards);
        let merge_line = "exec /opt/stagelight merge /home/me/study/job/parts/part-1.exr \
             /home/me/study/job/parts/part-2.exr /home/me/study/job/parts/part-3.exr \
             /home/me/study/job/parts/part-4.exr -o ref/door.exr";
        assert!(s.merge.lines().any(|l| l == merge_line), "{}", s.merge);
        // The merge waits for the shards' next jobs, by their name.
        assert!(
            s.merge.contains("/^door-1a2b-shard-[0-9]+$/")
                && s.merge.contains(
                    "sbatch --parsable --dependency=\"afterany:$left\" \
                     /home/me/study/job/merge.sbatch"
                ),
            "{}",
            s.merge
        );
        assert!(
            s.submit
                .contains("sbatch --parsable --dependency=afterany:\"$array\""),
            "{}",
            s.submit
        );
    }

    #[test]
    fn a_render_shard_does_not_go_on_and_keeps_its_threads() {
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
        assert!(!s.shards.contains("sbatch --parsable"), "{}", s.shards);
        assert!(!s.merge.contains("squeue"), "{}", s.merge);
        assert!(!s.shards.contains("SLURM_CPUS_PER_TASK"), "{}", s.shards);
        assert!(s.merge.contains("-o out.exr"), "{}", s.merge);
    }

    #[test]
    fn commands_that_cannot_be_sharded_are_refused() {
        for (command, says) in [
            (vec!["diff", "a.exr", "b.exr"], "not `diff`"),
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
            (vec!["compare", "s.ron", "--plan", "p.ron"], "--plan"),
        ] {
            let e = scripts(&options(&command)).unwrap_err().to_string();
            assert!(e.contains(says), "{command:?}: {e}");
        }
    }

    #[test]
    fn job_names_differ_between_job_folders() {
        let a = job_name("door ajar", Path::new("/home/me/job-a"));
        let b = job_name("door ajar", Path::new("/home/me/job-b"));
        assert!(
            a.starts_with("door_ajar-") && a.len() == "door_ajar-".len() + 4,
            "{a}"
        );
        assert_ne!(a, b);
        assert_eq!(a, job_name("door ajar", Path::new("/home/me/job-a")));
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
