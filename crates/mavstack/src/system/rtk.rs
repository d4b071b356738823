//! [`Rtk`]: RTK corrections to a system, in GPS_RTCM_DATA — one message at a time
//! ([`Rtk::inject`]), or an RTCM3 stream forwarded frame by frame ([`Rtk::forward`]) from a
//! base station's serial port, a TCP caster or a recorded file ([`RtcmSource`]).
//!
//! Every message gets the next 5-bit sequence id of the system's sender, and goes out in up
//! to four fragments as `mavstack_services::rtcm::fragments` cuts it (an empty last one
//! when its length is a multiple of 180 under 720); the messages of concurrent callers never
//! interleave their fragments. A stream is cut into frames by their CRC-24Q: what is not a
//! good frame is counted and never sent, and so is a frame too long for GPS_RTCM_DATA (over
//! 720 bytes).

use core::pin::Pin;
use core::time::Duration;
use std::path::PathBuf;

use mavstack_dialects::common::MavMessage;
use mavstack_services::rtcm::{Deframer, MAX_MESSAGE_LEN};
use mavstack_transport::conn::{ConnSpec, ConnSpecError};
use tokio::io::{AsyncRead, AsyncReadExt as _};

use super::{System, SystemError};

/// How much of a source is read at once.
const READ_LEN: usize = 4096;

/// RTK corrections to a system (from [`System::rtk`]).
#[derive(Clone, Debug)]
pub struct Rtk {
    system: System,
}

/// What a forwarding has done so far: counts since it began.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct RtkReport {
    /// Bytes read from the source.
    pub read: u64,
    /// Good RTCM3 frames found.
    pub frames: u64,
    /// Their bytes.
    pub frame_bytes: u64,
    /// Frames dropped as damaged (a bad CRC, or cut short at the end).
    pub damaged: u64,
    /// Bytes in no good frame.
    pub skipped: u64,
    /// Good frames too long for GPS_RTCM_DATA (over 720 bytes), not sent.
    pub too_long: u64,
    /// Frames sent, each as one GPS_RTCM_DATA message.
    pub sent: u64,
    /// GPS_RTCM_DATA messages those took.
    pub fragments: u64,
    /// The bytes of the frames sent.
    pub sent_bytes: u64,
    /// Time since the forwarding began.
    pub elapsed: Duration,
}

impl Rtk {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// Sends one RTCM message (usually one RTCM3 frame, up to 720 bytes) in GPS_RTCM_DATA,
    /// with the next sequence id; returns how many GPS_RTCM_DATA messages it took.
    ///
    /// # Errors
    /// [`SystemError::Rtcm`] for an empty message or one over 720 bytes (nothing is sent),
    /// [`SystemError::Stopped`].
    pub async fn inject(&self, message: &[u8]) -> Result<usize, SystemError> {
        let mut sender = self.system.inner.locks.rtk.lock().await;
        let parts = sender.fragments(message)?;
        for part in &parts {
            self.system.send(&MavMessage::GpsRtcmData(*part)).await?;
        }
        Ok(parts.len())
    }

    /// The sequence id the next message gets.
    pub async fn next_sequence(&self) -> u8 {
        self.system.inner.locks.rtk.lock().await.next_sequence()
    }

    /// Forwards the RTCM3 stream `source` until it ends: each good frame sent as soon as it
    /// is whole, what is not one counted. `progress` gets the counts every `every` and once
    /// at the end.
    ///
    /// # Errors
    /// [`SystemError::Io`] when the source cannot be read, [`SystemError::Stopped`].
    pub async fn forward<R: AsyncRead + Unpin>(
        &self,
        mut source: R,
        every: Duration,
        mut progress: impl FnMut(&RtkReport),
    ) -> Result<RtkReport, SystemError> {
        let began = tokio::time::Instant::now();
        let mut deframer = Deframer::new();
        let mut report = RtkReport::default();
        let mut buf = vec![0u8; READ_LEN];
        let every = every.clamp(Duration::from_millis(10), Duration::from_secs(86_400));
        let mut next = began + every;
        loop {
            let read = tokio::select! {
                read = source.read(&mut buf) => read.map_err(|source| SystemError::Io {
                    what: "cannot read the RTCM source".to_owned(),
                    source,
                })?,
                () = tokio::time::sleep_until(next) => {
                    report.elapsed = began.elapsed();
                    progress(&report);
                    next += every;
                    continue;
                }
            };
            if read == 0 {
                deframer.end();
            } else {
                report.read += read as u64;
                deframer.push(&buf[..read]);
            }
            while let Some(frame) = deframer.poll_frame() {
                if frame.len() > MAX_MESSAGE_LEN {
                    report.too_long += 1;
                    tracing::warn!(
                        bytes = frame.len(),
                        "an RTCM3 frame too long for GPS_RTCM_DATA, not sent"
                    );
                    continue;
                }
                report.fragments += self.inject(&frame).await? as u64;
                report.sent += 1;
                report.sent_bytes += frame.len() as u64;
            }
            let s = deframer.stats();
            report.frames = s.frames;
            report.frame_bytes = s.frame_bytes;
            report.damaged = s.damaged;
            report.skipped = s.skipped;
            if read == 0 {
                report.elapsed = began.elapsed();
                progress(&report);
                return Ok(report);
            }
        }
    }
}

/// Where an RTCM3 stream comes from: `tcp:HOST:PORT` (a caster or a base station's TCP
/// server), `serial:DEVICE:BAUD` (a base station's receiver), or a file (`file:PATH` or a
/// plain path).
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum RtcmSource {
    /// A TCP server to connect to.
    Tcp {
        /// Its host.
        host: String,
        /// Its port.
        port: u16,
    },
    /// A serial port.
    Serial {
        /// The device.
        device: String,
        /// Its baud rate.
        baud: u32,
    },
    /// A file, read to its end.
    File(PathBuf),
}

/// Why an RTCM source cannot be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RtcmSourceError {
    /// A connection string that does not parse.
    #[error("bad RTCM source")]
    Spec(#[from] ConnSpecError),
    /// A kind of connection that is not a byte stream to read.
    #[error("an RTCM source is tcp:HOST:PORT, serial:DEVICE:BAUD or a file, not {0:?}")]
    Kind(String),
    /// It could not be opened.
    #[error("cannot open {what}")]
    Open {
        /// The source as written.
        what: String,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

/// An open source: bytes to read.
pub type RtcmReader = Pin<Box<dyn AsyncRead + Send>>;

impl RtcmSource {
    /// Reads `tcp:HOST:PORT`, `serial:DEVICE:BAUD` (or `DEVICE,BAUD`), `file:PATH`, or a
    /// path.
    ///
    /// ```
    /// use mavstack::system::RtcmSource;
    /// assert_eq!(
    ///     RtcmSource::parse("tcp:caster.local:2101").unwrap(),
    ///     RtcmSource::Tcp { host: "caster.local".into(), port: 2101 }
    /// );
    /// assert!(matches!(RtcmSource::parse("base.rtcm3").unwrap(), RtcmSource::File(_)));
    /// assert!(RtcmSource::parse("udpin:0.0.0.0:1").is_err());
    /// ```
    ///
    /// # Errors
    /// [`RtcmSourceError::Spec`], [`RtcmSourceError::Kind`].
    pub fn parse(text: &str) -> Result<Self, RtcmSourceError> {
        let scheme = text
            .split_once(':')
            .map(|(s, _)| s.to_ascii_lowercase())
            .unwrap_or_default();
        let spec_like = text.contains("://")
            || text.contains(',')
            || matches!(
                scheme.as_str(),
                "tcp" | "serial" | "file" | "udp" | "udpin" | "udpout" | "udpbcast" | "tcpin"
            );
        if !spec_like {
            return Ok(Self::File(PathBuf::from(text)));
        }
        match text.parse::<ConnSpec>()? {
            ConnSpec::Tcp { host, port } => Ok(Self::Tcp { host, port }),
            ConnSpec::Serial { device, baud } => Ok(Self::Serial { device, baud }),
            ConnSpec::File { path, .. } => Ok(Self::File(path)),
            _ => Err(RtcmSourceError::Kind(text.to_owned())),
        }
    }

    /// Opens it for reading.
    ///
    /// # Errors
    /// [`RtcmSourceError::Open`] with the OS error.
    pub async fn open(&self) -> Result<RtcmReader, RtcmSourceError> {
        let open = |source| RtcmSourceError::Open {
            what: self.to_string(),
            source,
        };
        Ok(match self {
            Self::Tcp { host, port } => Box::pin(
                tokio::net::TcpStream::connect((host.as_str(), *port))
                    .await
                    .map_err(open)?,
            ),
            Self::Serial { device, baud } => {
                use tokio_serial::SerialPortBuilderExt as _;
                let port = tokio_serial::new(device, *baud)
                    .open_native_async()
                    .map_err(|e| open(e.into()))?;
                Box::pin(port)
            }
            Self::File(path) => Box::pin(tokio::fs::File::open(path).await.map_err(open)?),
        })
    }
}

impl core::fmt::Display for RtcmSource {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Tcp { host, port } => write!(f, "tcp:{host}:{port}"),
            Self::Serial { device, baud } => write!(f, "serial:{device}:{baud}"),
            Self::File(path) => write!(f, "{}", path.display()),
        }
    }
}
