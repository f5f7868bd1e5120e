//! `spwi-sim layout`: writes a floor to a TOML file — a generated one, or the built-in
//! or a given one mirrored — so it can be read, rendered, edited and passed to any
//! tool with `--layouts FILE`.

use anyhow::{bail, Result};
use spwi_world::generate;
use spwi_world::layout::Layout;

/// The arguments of `spwi-sim layout`.
#[derive(clap::Args, Debug)]
pub struct LayoutArgs {
    /// Generate the floor of this generator seed (`train:N` is seed N).
    #[arg(long, value_name = "SEED", conflicts_with = "mirror")]
    pub generate: Option<u64>,
    /// Mirror a floor (x → width − x): the built-in one, or FILE.
    #[arg(long, value_name = "FILE", num_args = 0..=1, default_missing_value = "")]
    pub mirror: Option<std::path::PathBuf>,
    #[arg(long)]
    pub out: std::path::PathBuf,
}

/// `spwi-sim layout`.
pub fn main(a: LayoutArgs) -> Result<()> {
    let layout = match (&a.generate, &a.mirror) {
        (Some(seed), _) => generate::layout(*seed),
        (None, Some(p)) if p.as_os_str().is_empty() => Layout::default_layout().mirrored(),
        (None, Some(p)) => Layout::load(p)?.mirrored(),
        (None, None) => bail!("say what to write: --generate SEED or --mirror [FILE]"),
    };
    layout.validate()?;
    std::fs::write(&a.out, layout.to_toml()).map_err(|e| anyhow::anyhow!("--out {}: {e}", a.out.display()))?;
    println!(
        "wrote {} ({} × {} m, {} obstacles, close pairs {:?})",
        a.out.display(),
        layout.floor.size[0],
        layout.floor.size[1],
        layout.obstacles.len(),
        layout.close_pairs()
    );
    Ok(())
}
