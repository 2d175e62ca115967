//! [`Stream`]: the `/v1/stream` WebSocket (`DESIGN.md`, "WebSocket messages"): views and
//! acks out, the server's resets, deltas and errors in, as JSON text frames. A close frame
//! from the server is a [`StreamError::Closed`] with its code and reason.

use futures_util::{SinkExt, StreamExt};
use horizon_protocol::{ClientMessage, ServerMessage, View};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
use tokio_tungstenite::tungstenite::protocol::CloseFrame;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

use crate::http::one_line;

/// An open `/v1/stream` connection.
#[derive(Debug)]
pub struct Stream {
    ws: WebSocketStream<MaybeTlsStream<TcpStream>>,
}

impl Stream {
    /// Opens `/v1/stream` on the server at `base_url` (`http://host:port`; `ws://` also
    /// works).
    ///
    /// # Errors
    /// [`StreamError::BadUrl`] or [`StreamError::WebSocket`] if the handshake fails.
    pub async fn connect(base_url: &str) -> Result<Self, StreamError> {
        let url = stream_url(base_url)?;
        let (ws, _) = tokio_tungstenite::connect_async(url.as_str()).await?;
        Ok(Self { ws })
    }

    /// Sends a view: where the viewer is now.
    ///
    /// # Errors
    /// [`StreamError::WebSocket`] if it cannot be sent.
    pub async fn send_view(&mut self, id: u64, view: &View) -> Result<(), StreamError> {
        self.send(&ClientMessage::View { id, view: *view }).await
    }

    /// Tells the server every message up to `seq` has been applied.
    ///
    /// # Errors
    /// [`StreamError::WebSocket`] if it cannot be sent.
    pub async fn ack(&mut self, seq: u64) -> Result<(), StreamError> {
        self.send(&ClientMessage::Ack { seq }).await
    }

    /// The server's next message. Pings and pongs are answered and skipped.
    ///
    /// Cancel-safe: a `next` dropped before it completes loses no message, so it can be one
    /// branch of a `tokio::select!`.
    ///
    /// # Errors
    /// [`StreamError::Closed`] for a close frame (with its code and reason),
    /// [`StreamError::Ended`] if the connection ends without one, [`StreamError::Json`] for a
    /// text frame that is not a server message, [`StreamError::Binary`] for a binary frame.
    pub async fn next(&mut self) -> Result<ServerMessage, StreamError> {
        loop {
            let Some(frame) = self.ws.next().await else {
                return Err(StreamError::Ended);
            };
            match frame? {
                Message::Text(text) => {
                    return serde_json::from_str(text.as_str()).map_err(|error| StreamError::Json {
                        error,
                        text: one_line(text.as_str(), 200),
                    })
                }
                Message::Close(frame) => {
                    return Err(match frame {
                        Some(f) => StreamError::Closed {
                            code: f.code.into(),
                            reason: f.reason.to_string(),
                        },
                        None => StreamError::Closed {
                            code: u16::from(CloseCode::Status),
                            reason: String::new(),
                        },
                    })
                }
                Message::Binary(bytes) => return Err(StreamError::Binary(bytes.len())),
                Message::Ping(_) | Message::Pong(_) | Message::Frame(_) => {}
            }
        }
    }

    /// Closes the connection with a normal close frame and waits (briefly) for the server's.
    ///
    /// # Errors
    /// [`StreamError::WebSocket`] if the close cannot be sent.
    pub async fn close(mut self) -> Result<(), StreamError> {
        let frame = CloseFrame {
            code: CloseCode::Normal,
            reason: "".into(),
        };
        match self.ws.close(Some(frame)).await {
            Ok(())
            | Err(tokio_tungstenite::tungstenite::Error::ConnectionClosed)
            | Err(tokio_tungstenite::tungstenite::Error::AlreadyClosed) => {}
            Err(e) => return Err(e.into()),
        }
        // Drain until the server's close frame or the end, without waiting long.
        let drain = async { while let Some(Ok(_)) = self.ws.next().await {} };
        let _ = tokio::time::timeout(std::time::Duration::from_secs(2), drain).await;
        Ok(())
    }

    async fn send(&mut self, message: &ClientMessage) -> Result<(), StreamError> {
        let text = serde_json::to_string(message).map_err(|error| StreamError::Json {
            error,
            text: format!("{message:?}"),
        })?;
        self.ws.send(Message::text(text)).await?;
        Ok(())
    }
}

/// `ws://host:port/v1/stream` for `http://host:port`.
fn stream_url(base_url: &str) -> Result<String, StreamError> {
    let base = base_url.trim_end_matches('/');
    let rest = if let Some(rest) = base.strip_prefix("http://") {
        format!("ws://{rest}")
    } else if let Some(rest) = base.strip_prefix("https://") {
        format!("wss://{rest}")
    } else if base.starts_with("ws://") || base.starts_with("wss://") {
        base.to_owned()
    } else {
        return Err(StreamError::BadUrl(base_url.to_owned()));
    };
    Ok(format!("{rest}/v1/stream"))
}

/// Why a stream failed.
#[derive(Debug, thiserror::Error)]
pub enum StreamError {
    /// The server closed the connection with a close frame.
    #[error("the server closed the stream: {code} {reason}")]
    Closed {
        /// The close code (1008 policy, 1009 too big, 1000 normal, ...).
        code: u16,
        /// The reason: the contract's error code for a limit.
        reason: String,
    },
    /// The connection ended without a close frame.
    #[error("the stream ended without a close frame")]
    Ended,
    /// A text frame that is not a server message (or a message that could not be encoded).
    #[error("not a stream message ({error}): {text}")]
    Json {
        /// Why it did not parse.
        error: serde_json::Error,
        /// The start of the frame.
        text: String,
    },
    /// A binary frame, which the protocol never sends.
    #[error("the server sent a binary frame of {0} bytes")]
    Binary(usize),
    /// The WebSocket failed (handshake, I/O, protocol).
    #[error("websocket: {0}")]
    WebSocket(#[from] tokio_tungstenite::tungstenite::Error),
    /// The base URL is not an `http://` or `ws://` URL.
    #[error("{0:?} is not an http:// or ws:// URL")]
    BadUrl(String),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stream_url_follows_the_base_url() {
        assert_eq!(
            stream_url("http://127.0.0.1:8080/").ok().as_deref(),
            Some("ws://127.0.0.1:8080/v1/stream")
        );
        assert_eq!(
            stream_url("ws://h:1").ok().as_deref(),
            Some("ws://h:1/v1/stream")
        );
        assert!(stream_url("ftp://h").is_err());
    }
}
