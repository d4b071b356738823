//! `mavstack signing setup|remove`: turn message signing on or off with a remote system and
//! prove it, over `mavstack::system::System`.
//!
//! `setup` sends SETUP_SIGNING (the key and a timestamp of now) over an unsigned link — a
//! secure one such as USB, since the key travels in clear — then signs the link and asks for
//! AUTOPILOT_VERSION: on a signed link only answers that verify with the key get through, so
//! an answer proves both ends sign. `remove` connects signed with the current key, sends the
//! all-zero key (signed, as the system requires) and proves that an unsigned request is
//! answered again.

use anyhow::anyhow;
use clap::Subcommand;
use serde_json::json;

use crate::link_cmd::runtime;
use crate::remote::{RemoteArgs, close, connect, print_lines};
use crate::vehicle_cmd::secret_key;
use crate::{Failure, fail, other};

#[derive(Debug, Subcommand)]
pub(crate) enum SigningAction {
    /// Send SETUP_SIGNING with `--key` over the (unsigned, secure) link, then sign the link
    /// and prove it: a signed request gets a signed answer.
    Setup {
        #[command(flatten)]
        remote: RemoteArgs,
    },
    /// Connect signed with `--key` (the key in use), send the all-zero key, then prove that
    /// an unsigned request is answered.
    Remove {
        #[command(flatten)]
        remote: RemoteArgs,
    },
}

pub(crate) fn signing(action: &SigningAction) -> Result<(), Failure> {
    let (remote, setup) = match action {
        SigningAction::Setup { remote } => (remote, true),
        SigningAction::Remove { remote } => (remote, false),
    };
    let Some(hex) = remote.key.as_deref() else {
        return Err(Failure::Input(anyhow!(
            "signing {}: --key HEX (64 hex digits) is required",
            if setup { "setup" } else { "remove" }
        )));
    };
    let key = secret_key(hex, "--key")?;
    // `setup` reaches the system unsigned; `remove` signed with the key in use.
    let mut args = remote.clone();
    if setup {
        args.key = None;
    }
    runtime()?.block_on(async {
        let session = connect(&args).await?;
        let signing = session.system().signing();
        let check = if setup {
            signing.setup(key, args.link_id).await
        } else {
            signing.remove().await
        }
        .map_err(fail);
        close(session).await?;
        let check = check?;
        let what = if setup { "on" } else { "off" };
        let how = if setup { "signed" } else { "unsigned" };
        let line = if args.json {
            json!({
                "signing": what,
                "asked": check.asked,
                "answered": check.answered,
                "proven": check.proven(),
                "statustext": check.statustext,
            })
            .to_string()
        } else {
            format!(
                "signing {what}: {}/{} answers {how}",
                check.answered, check.asked
            )
        };
        print_lines(&[line])?;
        if check.proven() {
            Ok(())
        } else {
            let why = if check.statustext.is_empty() {
                String::new()
            } else {
                format!(" (the vehicle said: {})", check.statustext.join("; "))
            };
            Err(other(format!(
                "signing {what} not proven: {} of {} requests answered {how}{why}",
                check.answered, check.asked
            )))
        }
    })
}
