//! Submissions on the context's queue: blocking ones (`submit_and_wait`, every pathgrad call), and
//! ones that wait on and signal an engine's timeline semaphores (`submit`, returning a [`Pending`]).

use std::sync::Arc;

use ash::vk;

use super::{Context, FENCE_TIMEOUT_SECONDS, Owner};
use crate::error::{Error, Result, VkResultExt};

/// Timeline semaphores a [`Context::submit`] waits on and signals.
#[derive(Clone, Debug, Default)]
pub struct SubmitSync {
    /// (semaphore, value to wait for, stages that wait).
    pub wait: Vec<(vk::Semaphore, u64, vk::PipelineStageFlags)>,
    /// (semaphore, value to signal when the work is done).
    pub signal: Vec<(vk::Semaphore, u64)>,
}

/// Work submitted by [`Context::submit`] and not yet waited for. Dropping it waits (with the
/// context's finite timeout) before its command buffer is freed. Thread safety: `Send + Sync`;
/// it may be waited for on another thread.
#[must_use = "dropping a Pending waits for it"]
pub struct Pending {
    ctx: Arc<Context>,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    what: String,
}

const _: fn() = || {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<Pending>();
};

impl Pending {
    /// Whether the work has finished (without blocking).
    pub fn is_done(&self) -> bool {
        // SAFETY: the fence belongs to this device.
        self.fence == vk::Fence::null() || unsafe { self.ctx.device.get_fence_status(self.fence) }.unwrap_or(true)
    }

    /// Waits for the work.
    ///
    /// # Errors
    /// [`Error::Timeout`] after [`FENCE_TIMEOUT_SECONDS`]; Vulkan failures.
    pub fn wait(mut self) -> Result<()> {
        self.wait_ref()
    }

    fn wait_ref(&mut self) -> Result<()> {
        if self.fence == vk::Fence::null() {
            return Ok(());
        }
        let d = &self.ctx.device;
        // SAFETY: the fence was submitted.
        let result = match unsafe { d.wait_for_fences(&[self.fence], true, FENCE_TIMEOUT_SECONDS * 1_000_000_000) } {
            Ok(()) => Ok(()),
            Err(vk::Result::TIMEOUT) => Err(Error::Timeout { what: self.what.clone(), seconds: FENCE_TIMEOUT_SECONDS }),
            Err(result) => Err(Error::Vulkan { call: "vkWaitForFences", result }),
        };
        if result.is_ok() {
            // SAFETY: signalled: nothing uses the fence any more.
            unsafe { d.destroy_fence(self.fence, None) };
            self.fence = vk::Fence::null();
        }
        result
    }
}

impl Drop for Pending {
    fn drop(&mut self) {
        if self.wait_ref().is_err() {
            // A timed-out or failed wait: the device must finish before the buffer goes. Owned
            // devices are waited idle; on a borrowed one the fence and buffer are leaked instead.
            if matches!(self.ctx.owner, Owner::Pathgrad { .. }) {
                // SAFETY: valid device.
                let _ = unsafe { self.ctx.device.device_wait_idle() };
            } else {
                tracing::error!(what = %self.what, "pathgrad work on a borrowed device did not finish; its command buffer is leaked");
                return;
            }
            // SAFETY: the device is idle.
            unsafe { self.ctx.device.destroy_fence(self.fence, None) };
        }
        let pool = self.ctx.command_pool.lock().unwrap_or_else(|p| p.into_inner());
        // SAFETY: the work is done; the pool is guarded by the mutex.
        unsafe { self.ctx.device.free_command_buffers(*pool, &[self.cmd]) };
    }
}

impl Context {
    /// Records commands with `record`, submits them and waits (with a finite timeout).
    ///
    /// # Errors
    /// Vulkan failures, or [`Error::Timeout`] if the GPU does not finish in [`FENCE_TIMEOUT_SECONDS`].
    pub fn submit_and_wait(&self, what: &str, record: impl FnOnce(vk::CommandBuffer)) -> Result<()> {
        let pool = self.command_pool.lock().unwrap_or_else(|p| p.into_inner());
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(*pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool belongs to this device and is guarded by the mutex.
        let cmd = unsafe { self.device.allocate_command_buffers(&alloc) }.vk("vkAllocateCommandBuffers")?[0];
        let result = self.record_submit(cmd, what, record);
        // SAFETY: the submission finished or failed; the buffer is not in use.
        unsafe { self.device.free_command_buffers(*pool, &[cmd]) };
        result
    }

    /// Records commands with `record` into a command buffer of pathgrad's and submits them on the
    /// context's queue without waiting: the submission waits for each `(semaphore, value, stage)`
    /// of `sync.wait` and signals each `(semaphore, value)` of `sync.signal` (timeline semaphores),
    /// and the returned [`Pending`] owns the command buffer until the work is done.
    ///
    /// # Errors
    /// [`Error::NotEnabled`] naming `timelineSemaphore` when `sync` has semaphores but the device
    /// was created without timeline semaphores; Vulkan failures.
    pub fn submit(
        self: &Arc<Self>,
        what: &str,
        sync: &SubmitSync,
        record: impl FnOnce(vk::CommandBuffer),
    ) -> Result<Pending> {
        let uses_semaphores = !sync.wait.is_empty() || !sync.signal.is_empty();
        if uses_semaphores && !self.info.timeline_semaphores {
            return Err(Error::NotEnabled {
                device: self.info.name.clone(),
                missing: vec!["timelineSemaphore".into()],
            });
        }
        let cmd = {
            let pool = self.command_pool.lock().unwrap_or_else(|p| p.into_inner());
            let alloc = vk::CommandBufferAllocateInfo::default()
                .command_pool(*pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1);
            // SAFETY: the pool belongs to this device and is guarded by the mutex.
            unsafe { self.device.allocate_command_buffers(&alloc) }.vk("vkAllocateCommandBuffers")?[0]
        };
        let mut pending = Pending { ctx: self.clone(), cmd, fence: vk::Fence::null(), what: what.to_string() };
        let begin = vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: fresh command buffer.
        unsafe { self.device.begin_command_buffer(cmd, &begin) }.vk("vkBeginCommandBuffer")?;
        record(cmd);
        // SAFETY: recording started above.
        unsafe { self.device.end_command_buffer(cmd) }.vk("vkEndCommandBuffer")?;
        // SAFETY: valid device.
        let fence = unsafe { self.device.create_fence(&vk::FenceCreateInfo::default(), None) }.vk("vkCreateFence")?;
        pending.fence = fence;
        let wait_semaphores: Vec<vk::Semaphore> = sync.wait.iter().map(|w| w.0).collect();
        let wait_values: Vec<u64> = sync.wait.iter().map(|w| w.1).collect();
        let wait_stages: Vec<vk::PipelineStageFlags> = sync.wait.iter().map(|w| w.2).collect();
        let signal_semaphores: Vec<vk::Semaphore> = sync.signal.iter().map(|s| s.0).collect();
        let signal_values: Vec<u64> = sync.signal.iter().map(|s| s.1).collect();
        let mut timeline = vk::TimelineSemaphoreSubmitInfo::default()
            .wait_semaphore_values(&wait_values)
            .signal_semaphore_values(&signal_values);
        let cmds = [cmd];
        let mut submit = vk::SubmitInfo::default()
            .command_buffers(&cmds)
            .wait_semaphores(&wait_semaphores)
            .wait_dst_stage_mask(&wait_stages)
            .signal_semaphores(&signal_semaphores);
        if self.info.timeline_semaphores {
            submit = submit.push_next(&mut timeline);
        }
        let queue = self.queue.lock().unwrap_or_else(|p| p.into_inner());
        // SAFETY: the queue is externally synchronised by the mutex; everything lives across the call.
        let submitted = unsafe { self.device.queue_submit(*queue, &[submit], fence) }.vk("vkQueueSubmit");
        drop(queue);
        if let Err(e) = submitted {
            // Nothing was submitted: the fence will never signal.
            pending.fence = vk::Fence::null();
            // SAFETY: the fence is not in use.
            unsafe { self.device.destroy_fence(fence, None) };
            return Err(e);
        }
        Ok(pending)
    }

    fn record_submit(&self, cmd: vk::CommandBuffer, what: &str, record: impl FnOnce(vk::CommandBuffer)) -> Result<()> {
        let begin = vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: fresh command buffer.
        unsafe { self.device.begin_command_buffer(cmd, &begin) }.vk("vkBeginCommandBuffer")?;
        record(cmd);
        // SAFETY: recording started above.
        unsafe { self.device.end_command_buffer(cmd) }.vk("vkEndCommandBuffer")?;
        // SAFETY: valid device.
        let fence = unsafe { self.device.create_fence(&vk::FenceCreateInfo::default(), None) }.vk("vkCreateFence")?;
        let cmds = [cmd];
        let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
        let result = {
            let queue = self.queue.lock().unwrap_or_else(|p| p.into_inner());
            // SAFETY: the queue is externally synchronised by the mutex.
            unsafe { self.device.queue_submit(*queue, &submit, fence) }.vk("vkQueueSubmit")
        }
        .and_then(|()| {
            // SAFETY: the fence was submitted above.
            match unsafe { self.device.wait_for_fences(&[fence], true, FENCE_TIMEOUT_SECONDS * 1_000_000_000) } {
                Ok(()) => Ok(()),
                Err(vk::Result::TIMEOUT) => {
                    Err(Error::Timeout { what: what.to_string(), seconds: FENCE_TIMEOUT_SECONDS })
                }
                Err(result) => Err(Error::Vulkan { call: "vkWaitForFences", result }),
            }
        });
        if matches!(result, Err(Error::Timeout { .. })) {
            // The GPU may still use the command buffer: wait for it before the fence and buffer go.
            // SAFETY: valid device.
            let _ = unsafe { self.device.device_wait_idle() };
        }
        // SAFETY: the fence is signalled or the device idle.
        unsafe { self.device.destroy_fence(fence, None) };
        result
    }
}
