//! Thread priorities: the loop's precise wake-ups and real-time priority, and the lowest
//! priority of work that must not delay it (live diagnosis, in the runtime and in the analysis
//! layer alike). Linux system calls on the calling thread, nothing else.
//!
//! Not here: when the loop wakes (`daemon::runtime::schedule`), which threads run what (`daemon`).

/// Makes the calling thread's sleeps end as close to their deadline as the kernel allows.
///
/// Linux lets a sleeping thread wake up to 50 µs late by default (timer slack) to batch
/// wake-ups; 1 ns asks for precise wake-ups. Harmless if refused.
#[allow(unsafe_code)]
pub fn tighten_timer_slack() {
    #[cfg(target_os = "linux")]
    // SAFETY: PR_SET_TIMERSLACK takes one integer argument and only affects the calling thread.
    unsafe {
        libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0);
    }
}

/// Puts the calling thread under SCHED_FIFO at `priority` (1-99), so ordinary work on a busy
/// machine cannot delay its wake-ups. Needs root or CAP_SYS_NICE; the error says so.
#[allow(unsafe_code)]
pub fn realtime_priority(priority: u8) -> std::io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        let param = libc::sched_param {
            sched_priority: libc::c_int::from(priority),
        };
        // SAFETY: pid 0 is the calling thread; `param` is a valid sched_param for SCHED_FIFO.
        let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
        if rc != 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(())
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = priority;
        Err(std::io::Error::new(
            std::io::ErrorKind::Unsupported,
            "SCHED_FIFO is Linux-only here",
        ))
    }
}

/// Puts the calling thread at the lowest priority: `SCHED_IDLE`, else nice 19.
#[allow(unsafe_code)]
pub fn lowest_priority() {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: plain system calls on the calling thread (pid 0) with a valid parameter.
    let idle = unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) } == 0;
    if !idle {
        // SAFETY: as above; on Linux PRIO_PROCESS with 0 is the calling thread.
        let _ = unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, 19) };
    }
}
