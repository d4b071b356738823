//! The traffic log (`NodeBuilder::log_dir`).

use std::path::PathBuf;

use mavstack_transport::{clock, tlog};

use super::NodeError;

pub(super) fn open_log(
    dir: &std::path::Path,
) -> Result<(PathBuf, tlog::Writer<std::fs::File>), NodeError> {
    let secs = clock::now().as_micros() / 1_000_000;
    let path = dir.join(format!("mavstack-{secs}.tlog"));
    let file = std::fs::File::create(&path).map_err(|source| NodeError::Log {
        path: path.clone(),
        source,
    })?;
    Ok((path, tlog::Writer::new(file)))
}
