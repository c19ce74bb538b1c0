//! The parsed arguments turned into the options structs the commands take.

use super::*;

impl ShardArgs {
    pub fn choice(&self) -> Option<crate::commands::ShardChoice> {
        use crate::commands::ShardChoice;
        match (self.shard, self.pass_range) {
            (Some((index, count)), _) => Some(ShardChoice::Shard { index, count }),
            (None, Some((first, end))) => Some(ShardChoice::Range { first, end }),
            (None, None) => None,
        }
    }
}

impl KernelArgs {
    /// `settings` with this kernel and wavefront.
    pub fn apply(&self, settings: RenderSettings) -> RenderSettings {
        RenderSettings {
            kernel: match self.kernel {
                KernelName::Wavefront => Kernel::Wavefront,
                KernelName::Megakernel => Kernel::Megakernel,
            },
            wavefront: self.wavefront.map(|n| n as usize),
            lanes: self.lanes,
            ..settings
        }
    }
}

impl MltArgs {
    pub fn options(&self) -> crate::integrators::MltOptions {
        crate::integrators::MltOptions {
            large_step: self.large_step,
            sigma: self.sigma,
            bootstrap: self.bootstrap,
            chains: self.chains,
            direct_spp: self.direct_spp,
            mutations: self.mutations,
            lens_min: self.lens_min,
        }
    }

    /// The flags of these options the command line gives (see `PhotonArgs::given`).
    pub fn given(&self) -> Vec<&'static str> {
        flags_given([
            ("--large-step", self.large_step.is_some()),
            ("--sigma", self.sigma.is_some()),
            ("--bootstrap", self.bootstrap.is_some()),
            ("--chains", self.chains.is_some()),
            ("--direct-spp", self.direct_spp.is_some()),
            ("--mutations", self.mutations.is_some()),
            ("--lens-min", self.lens_min.is_some()),
        ])
    }
}

/// The flags of `flags` that are given.
fn flags_given<const N: usize>(flags: [(&'static str, bool); N]) -> Vec<&'static str> {
    flags
        .into_iter()
        .filter_map(|(flag, given)| given.then_some(flag))
        .collect()
}

impl PhotonArgs {
    pub fn settings(&self) -> crate::integrators::PhotonSettings {
        let defaults = crate::integrators::PhotonSettings::default();
        crate::integrators::PhotonSettings {
            photons_per_pass: self.photons_per_pass.unwrap_or(defaults.photons_per_pass),
            alpha: self.alpha,
            radius: self.radius,
            eye_rays: self.eye_rays.unwrap_or(defaults.eye_rays),
            photons: self.photons.unwrap_or(defaults.photons),
            k: self.k.map_or(defaults.k, |k| k as usize),
            max_radius: self.max_radius,
            final_gather: !self.no_final_gather,
        }
    }

    /// The flags of these options the command line gives, for refusing them where the
    /// integrator does not read them.
    pub fn given(&self) -> Vec<&'static str> {
        flags_given([
            ("--photons-per-pass", self.photons_per_pass.is_some()),
            ("--alpha", self.alpha.is_some()),
            ("--radius", self.radius.is_some()),
            ("--eye-rays", self.eye_rays.is_some()),
            ("--photons", self.photons.is_some()),
            ("--k", self.k.is_some()),
            ("--max-radius", self.max_radius.is_some()),
            ("--no-final-gather", self.no_final_gather),
        ])
    }
}

impl MisName {
    pub fn heuristic(self) -> MisHeuristic {
        match self {
            MisName::Power => MisHeuristic::Power,
            MisName::Balance => MisHeuristic::Balance,
        }
    }
}

impl SlurmArgs {
    /// The options, after checking the command to shard as `stagelight` would parse it.
    pub(super) fn options(&self) -> Result<crate::commands::slurm::SlurmOptions> {
        let is_compare = crate::commands::slurm::check_command(&self.command)?.is_none();
        let binary = match &self.stagelight {
            Some(b) => b.clone(),
            None => std::env::current_exe().context("cannot find this stagelight binary")?,
        };
        let workdir = std::env::current_dir().context("cannot read the current folder")?;
        let dir = std::path::absolute(workdir.join(&self.output))
            .context("cannot find the job folder")?;
        let options = |name: String, plan| crate::commands::slurm::SlurmOptions {
            shards: self.shards,
            dir: dir.clone(),
            command: self.command.clone(),
            binary: binary.clone(),
            workdir: workdir.clone(),
            partition: self.partition.clone(),
            time_limit: self.time_limit.clone(),
            cpus_per_task: self.cpus_per_task,
            signal_seconds: self.signal_seconds,
            name: crate::commands::slurm::job_name(&name, &dir),
            plan,
        };
        if is_compare {
            let request = compare_request(&self.command)?;
            let name = match &request {
                crate::compare::shards::CompareRequest::Plain(o) => scene_stem(&o.scene),
                crate::compare::shards::CompareRequest::Thesis(_) => "thesis".into(),
            };
            let plan = crate::compare::shards::make_plan(
                &self.command,
                &request,
                self.shards,
                &dir.join("parts"),
                &workdir,
            )?;
            return Ok(options(name, Some(plan)));
        }
        let shard = format!("1/{}", self.shards);
        let line = ["stagelight"]
            .into_iter()
            .chain(self.command.iter().map(String::as_str))
            .chain(["--shard", &shard]);
        let parsed = Cli::try_parse_from(line).map_err(|e| {
            let text = e.render().to_string();
            anyhow::anyhow!(
                "the command to shard: {}",
                text.lines()
                    .next()
                    .unwrap_or_default()
                    .trim_start_matches("error: ")
            )
        })?;
        let spp = match parsed.command {
            Command::Render(a) => a.spp.unwrap_or(64),
            Command::Reference(a) => a.spp.unwrap_or(DEFAULT_REFERENCE_SPP),
            _ => unreachable!("check_command lets render and reference through"),
        };
        if self.shards > spp {
            anyhow::bail!(
                "--shards {}: more shards than the command's {spp} passes",
                self.shards
            );
        }
        let name = self
            .command
            .get(1)
            .map(|scene| scene_stem(std::path::Path::new(scene)))
            .unwrap_or_else(|| "stagelight".into());
        Ok(options(name, None))
    }
}

impl RenderArgs {
    pub fn options(&self) -> RenderOptions {
        let budget = match (self.spp, self.time) {
            (_, Some(t)) => Budget::Seconds(t),
            (Some(spp), None) => Budget::SamplesPerPixel(spp),
            (None, None) => Budget::SamplesPerPixel(64),
        };
        let output = self.output.clone().unwrap_or_else(|| {
            PathBuf::from("render").join(format!(
                "{}_{}.exr",
                scene_stem(&self.scene),
                self.integrator.as_str()
            ))
        });
        RenderOptions {
            scene: self.scene.clone(),
            integrator: self.integrator,
            budget,
            settings: self.kernel.apply(RenderSettings {
                seed: self.seed,
                sampler: self.sampler,
                max_depth: self.max_depth.unwrap_or(u32::MAX),
                mis: self.mis.heuristic(),
                strategy_images: self.strategy_images.is_some(),
                light_vertex_cache: self.light_vertex_cache.unwrap_or(0),
                moments: self.variance.is_some(),
                photons: self.photons.settings(),
                mlt: self.mlt.options(),
                ..RenderSettings::default()
            }),
            strategy_images: self.strategy_images.clone(),
            variance: self.variance.clone(),
            integrator_flags: [self.mlt.given(), self.photons.given()].concat(),
            output,
            shard: self.shard.choice(),
            threads: self.threads.map(|t| t as usize),
            quiet: self.quiet,
        }
    }
}

impl ReferenceArgs {
    pub fn options(&self) -> ReferenceOptions {
        let output = self.output.clone().unwrap_or_else(|| {
            PathBuf::from("reference").join(format!(
                "{}_{}.exr",
                scene_stem(&self.scene),
                self.integrator
            ))
        });
        let budget = match (self.spp, self.time) {
            (_, Some(t)) => ReferenceBudget::Seconds(t),
            (Some(spp), None) => ReferenceBudget::SamplesPerPixel(spp),
            (None, None) => ReferenceBudget::SamplesPerPixel(DEFAULT_REFERENCE_SPP),
        };
        ReferenceOptions {
            scene: self.scene.clone(),
            integrator: self.integrator,
            budget,
            settings: self.kernel.apply(RenderSettings {
                seed: self.seed,
                sampler: self.sampler,
                max_depth: self.max_depth.unwrap_or(u32::MAX),
                photons: self.photons.settings(),
                ..RenderSettings::default()
            }),
            integrator_flags: self.photons.given(),
            output,
            checkpoint_every: std::time::Duration::try_from_secs_f64(self.checkpoint_every)
                .unwrap_or(std::time::Duration::from_secs(
                    MAX_CHECKPOINT_SECONDS as u64,
                )),
            shard: self.shard.choice(),
            threads: self.threads.map(|t| t as usize),
            quiet: self.quiet,
        }
    }
}

impl CompareArgs {
    pub fn options(&self) -> Result<CompareOptions> {
        let scene = self
            .scene
            .clone()
            .context("a scene file is needed (or --preset thesis)")?;
        let output = self
            .output
            .clone()
            .unwrap_or_else(|| PathBuf::from("compare").join(scene_stem(&scene)));
        Ok(CompareOptions {
            scene,
            reference: self.reference.clone(),
            integrators: self.integrators.clone(),
            unit: match self.budget_unit {
                BudgetUnitArg::Seconds => BudgetUnit::Seconds,
                BudgetUnitArg::Spp => BudgetUnit::Spp,
            },
            budgets: self.budgets.clone(),
            settings: self.kernel.apply(RenderSettings {
                seed: self.seed,
                sampler: self.sampler,
                max_depth: self.max_depth.unwrap_or(u32::MAX),
                photons: self.photons.settings(),
                ..RenderSettings::default()
            }),
            reference_spp: self.reference_spp,
            output,
            threads: self.threads.map(|t| t as usize),
            quiet: self.quiet,
        })
    }

    pub(super) fn thesis_options(&self) -> ThesisOptions {
        ThesisOptions {
            scenes_dir: self.scenes_dir.clone(),
            output: self
                .output
                .clone()
                .unwrap_or_else(|| PathBuf::from("compare").join("thesis")),
            seed: self.seed,
            max_depth: self.max_depth.unwrap_or(u32::MAX),
            photons: self.photons.settings(),
            photon_budgets: self.thesis_photons.clone(),
            reference_spp: self.reference_spp,
            references: self.references.clone(),
            threads: self.threads.map(|t| t as usize),
            quiet: self.quiet,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// The photon options' help states their defaults in words (clap's own default would mark
    /// every one as given); those words must be the defaults `settings` fills in.
    #[test]
    fn photon_option_help_states_the_defaults_settings_use() {
        let defaults = crate::integrators::PhotonSettings::default();
        let thousands = |n: u64| {
            let digits = n.to_string();
            let mut out = String::new();
            for (i, c) in digits.chars().enumerate() {
                if i > 0 && (digits.len() - i).is_multiple_of(3) {
                    out.push(',');
                }
                out.push(c);
            }
            out
        };
        let command = Cli::command();
        let render = command.find_subcommand("render").expect("a render command");
        let help = |long: &str| {
            render
                .get_arguments()
                .find(|a| a.get_long() == Some(long))
                .and_then(|a| a.get_help())
                .map(|h| h.to_string())
                .unwrap_or_else(|| panic!("--{long} has help"))
        };
        for (long, default) in [
            ("photons-per-pass", thousands(defaults.photons_per_pass)),
            ("photons", thousands(defaults.photons)),
            ("eye-rays", defaults.eye_rays.to_string()),
            ("k", defaults.k.to_string()),
        ] {
            let text = help(long);
            assert!(
                text.contains(&format!("default {default})")),
                "--{long}: {text}"
            );
        }
        let given = Cli::try_parse_from(["stagelight", "render", "s.ron"]).expect("parses");
        let Command::Render(args) = given.command else {
            panic!("a render command")
        };
        assert_eq!(args.photons.settings(), defaults);
        assert!(args.photons.given().is_empty());
    }
}
