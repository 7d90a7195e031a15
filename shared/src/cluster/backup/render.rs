//! The node renders the jobs that arrive over the backup line: the same [`RunRenderer`]
//! (the `links_core` tracer) the SPI path runs, piece by piece (at most a scanline piece of
//! [`OUTBOX_PIXELS`] each), every piece handed to the node's outbox for the RC's polls.
//!
//! Three steps, so that firmware which shares the node state with an interrupt-driven line
//! task holds it only briefly: [`BackupRender::next`] (the next piece: needs the node),
//! [`BackupRender::render`] (the pixels: needs only the scene bytes and the renderer, so the
//! firmware renders with the bank taken out of the node and the line task free to answer),
//! [`BackupRender::finish`] (the pixels into the outbox). [`BackupRender::render_pending`]
//! runs all three on a node that holds its bank.

use super::{BackupError, BackupNode, OUTBOX_PIXELS};
use crate::cluster::node::RunRenderer;
use crate::cluster::wire::Job;
use crate::image::{ImageError, SceneView};
use crate::render::{RenderError, Rgb8, Stats};
use core::fmt;

/// One piece of a job: `len` pixels of scanline `y` from column `x`; `last`: the job's last.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Piece {
    pub job: Job,
    pub y: u16,
    pub x: u16,
    pub len: u16,
    pub last: bool,
    /// It ends its scanline piece of the job (a piece longer than the caller's buffer is
    /// rendered in parts).
    pub ends_row: bool,
    /// The scene it renders: frame and CRC-32 ([`super::NodeScene::key`]).
    pub scene: (u16, u32),
}

/// Why the node could not render a piece of a backup job.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BackupRenderError {
    /// The scene received over the line is no usable SceneImage.
    Scene(ImageError),
    /// The job is for a frame whose scene the node does not hold, or its region lies
    /// outside the frame.
    BadJob { job: u32 },
    /// The tracer failed.
    Render(RenderError),
    /// The outbox refused the pixels (or the buffer is too small for the piece).
    Outbox(BackupError),
}

impl fmt::Display for BackupRenderError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BackupRenderError::Scene(e) => write!(f, "backup scene: {e:?}"),
            BackupRenderError::BadJob { job } => {
                write!(f, "backup job {job} does not fit the scene the node holds")
            }
            BackupRenderError::Render(e) => write!(f, "backup render: {e:?}"),
            BackupRenderError::Outbox(e) => write!(f, "backup outbox: {e}"),
        }
    }
}

impl core::error::Error for BackupRenderError {}

/// The node's progress through its backup job, and the scene it last validated.
#[derive(Clone, Copy, Debug, Default)]
pub struct BackupRender {
    /// The job, its scanline piece index and the pixels of that piece already done.
    job: Option<(Job, u32, u32)>,
    /// Frame and CRC of the scene that passed [`SceneView::new`].
    checked: Option<(u16, u32)>,
}

impl BackupRender {
    pub const fn new() -> Self {
        Self {
            job: None,
            checked: None,
        }
    }

    /// The job being rendered.
    pub fn job(&self) -> Option<Job> {
        self.job.map(|j| j.0)
    }

    /// The next piece to render (at most `max` pixels), taking a job the RC handed over
    /// (a new id replaces the current job). `None`: nothing to do now (no job, the outbox
    /// still holds pixels, or the scene is not complete).
    pub fn next(
        &mut self,
        node: &mut BackupNode<'_>,
        max: usize,
    ) -> Result<Option<Piece>, BackupRenderError> {
        if let Some(j) = node.take_job() {
            if self.job.is_none_or(|c| c.0.id != j.id) {
                self.job = Some((j, 0, 0));
            }
        }
        let Some((job, i, done)) = self.job else {
            return Ok(None);
        };
        let (Some(key), Some(_)) = (node.scene.key(), node.scene.ready()) else {
            return Ok(None);
        };
        if !node.outbox_free() {
            return Ok(None);
        }
        if key.0 != job.frame {
            self.job = None;
            return Err(BackupRenderError::BadJob { job: job.id });
        }
        let width = scene_width(node)?;
        let Some((y, x, len)) = job.region.piece(width, i) else {
            self.job = None;
            return Ok(None);
        };
        let max = max.clamp(1, OUTBOX_PIXELS) as u32;
        let n = (len - done.min(len)).min(max);
        let last_of_piece = done + n >= len;
        let last = last_of_piece && job.region.piece(width, i + 1).is_none();
        let fits = |v: u32| u16::try_from(v).map_err(|_| BackupRenderError::BadJob { job: job.id });
        Ok(Some(Piece {
            job,
            y: fits(y)?,
            x: fits(x + done)?,
            len: fits(n)?,
            last,
            ends_row: last_of_piece,
            scene: key,
        }))
    }

    /// Render `piece` of `scene` (the node's scene bytes, [`super::NodeScene::ready`]) into
    /// `out` (at least `piece.len` pixels): validated once per scene, then opened cheaply.
    pub fn render<R: RunRenderer>(
        &mut self,
        piece: &Piece,
        scene: &[u8],
        renderer: &mut R,
        out: &mut [Rgb8],
    ) -> Result<Stats, BackupRenderError> {
        let view = if self.checked == Some(piece.scene) {
            SceneView::open_validated(scene)
        } else {
            // A new scene, perhaps in the bank (and frame number) of the last one: the
            // renderer's caches go.
            self.checked = None;
            renderer.forget();
            SceneView::new(scene)
        }
        .map_err(BackupRenderError::Scene)?;
        self.checked = Some(piece.scene);
        let out = out
            .get_mut(..piece.len as usize)
            .ok_or(BackupRenderError::Outbox(BackupError::TooLong))?;
        let (y, x) = (piece.y as u32, piece.x as u32);
        renderer
            .render(view, piece.scene.0, y, x, out)
            .map_err(BackupRenderError::Render)
    }

    /// Hand the rendered piece to the node's outbox and move on.
    pub fn finish(
        &mut self,
        node: &mut BackupNode<'_>,
        piece: &Piece,
        out: &[Rgb8],
    ) -> Result<(), BackupRenderError> {
        let px = out
            .get(..piece.len as usize)
            .ok_or(BackupRenderError::Outbox(BackupError::TooLong))?;
        node.push_pixels(&piece.job, piece.y, piece.x, px.as_flattened(), piece.last)
            .map_err(BackupRenderError::Outbox)?;
        if let Some((job, i, done)) = self.job.as_mut() {
            if job.id == piece.job.id {
                *done += piece.len as u32;
                if piece.ends_row {
                    (*i, *done) = (*i + 1, 0);
                }
                if piece.last {
                    self.job = None;
                }
            }
        }
        Ok(())
    }

    /// Render the next piece of the node's job, if there is one, into its outbox (a node
    /// holding its bank). Returns the operations counted (`None`: nothing to do).
    pub fn render_pending<R: RunRenderer>(
        &mut self,
        node: &mut BackupNode<'_>,
        renderer: &mut R,
        out: &mut [Rgb8],
    ) -> Result<Option<Stats>, BackupRenderError> {
        let Some(piece) = self.next(node, out.len())? else {
            return Ok(None);
        };
        let (_, scene) = node
            .scene
            .ready()
            .ok_or(BackupRenderError::BadJob { job: piece.job.id })?;
        let stats = self.render(&piece, scene, renderer, out)?;
        self.finish(node, &piece, out)?;
        Ok(Some(stats))
    }
}

/// The frame width of the node's scene (its camera; the header and section table are
/// checked, the full validation waits for the render).
fn scene_width(node: &BackupNode<'_>) -> Result<u32, BackupRenderError> {
    let (_, bytes) = node
        .scene
        .ready()
        .ok_or(BackupRenderError::Outbox(BackupError::TooLong))?;
    let view = SceneView::open_validated(bytes).map_err(BackupRenderError::Scene)?;
    Ok(view.camera::<f32>().width)
}
