//! `roomlight demo` (for now): the distributed loop on a synthetic room.

use anyhow::Result;

/// Options of the demo.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// A smaller room (for tests).
    #[arg(long)]
    pub quick: bool,
}

pub fn run(_args: &DemoArgs) -> Result<()> {
    Ok(())
}
