/* parallel.c — rows of an image over POSIX threads (or the calling thread
 * alone when built with THREADS=0).  Rows are handed out one at a time, so
 * the result never depends on the number of threads. */
#include "internal.h"

#ifdef RTP_HAVE_THREADS
#include <pthread.h>
#endif

typedef struct pool {
    int nrows, next, done, stop;
    int relay, finished; /* the caller relays progress; workers ended */
    int locking;         /* the lock was made (else one thread alone) */
    int cancelled;       /* cancel said to stop (stop is set too) */
    int reported;        /* rows done at the calling thread's last report */
    int relayed;         /* the same for the relaying caller (-1: none yet) */
    rtpi_row_fn fn;
    void *const *ctx;
    void (*progress)(void *user, double done);
    int (*cancel)(void *user);
    void *progress_user;
#ifdef RTP_HAVE_THREADS
    pthread_mutex_t lock;
    pthread_cond_t cv; /* (relay: a row done, a worker ended) */
#endif
} pool;

typedef struct job {
    pool *p;
    void *ctx;
    int is_main;
} job;

static void pool_lock(pool *p)
{
#ifdef RTP_HAVE_THREADS
    if (p->locking)
        pthread_mutex_lock(&p->lock);
#else
    (void)p;
#endif
}

static void pool_unlock(pool *p)
{
#ifdef RTP_HAVE_THREADS
    if (p->locking)
        pthread_mutex_unlock(&p->lock);
#else
    (void)p;
#endif
}

/* Asks the caller's cancel (from the calling thread, as progress); a yes
   stops the rows not yet begun. */
static void poll_cancel(pool *p)
{
    if (p->cancel && !p->cancelled && p->cancel(p->progress_user)) {
        pool_lock(p);
        p->stop = 1;
        p->cancelled = 1;
        pool_unlock(p);
    }
}

/* Progress and cancel are called at most about this many times a call:
   a re-trace's chunks of 64 samples were 16,385 calls for a 1024x1024
   camera edit, and a UI's progress of 1 ms made that 1.5 s edit 21.9 s
   on one thread. */
#define REPORTS 1000

/* Whether `done` rows are worth a report after a report at `last` (a
   new thousandth, or the end). */
static int worth_report(const pool *p, int done, int last)
{
    return done == p->nrows || last < 0 ||
           (long long)done * REPORTS / p->nrows != (long long)last * REPORTS / p->nrows;
}

static void run(job *j)
{
    pool *p = j->p;
    for (;;) {
        int row, done, stop;
        pool_lock(p);
        row = p->stop ? p->nrows : p->next++;
        pool_unlock(p);
        if (row >= p->nrows)
            break;
        stop = p->fn(j->ctx, row) != 0;
        pool_lock(p);
        done = ++p->done;
        if (stop)
            p->stop = 1;
#ifdef RTP_HAVE_THREADS
        /* (the waiting caller woken only for a report it will make: a
           signal a row woke it 513 times a move for nothing where no
           progress or cancel was asked, each wake-up a context switch
           on a core the other worker wanted) */
        if (p->relay && (p->progress || p->cancel) && worth_report(p, done, p->relayed))
            pthread_cond_signal(&p->cv);
#endif
        pool_unlock(p);
        if (j->is_main && worth_report(p, done, p->reported)) {
            if (p->progress)
                p->progress(p->progress_user, (double)done / p->nrows);
            p->reported = done;
            poll_cancel(p);
        }
    }
}

#ifdef RTP_HAVE_THREADS
static void *thread_main(void *arg)
{
    job *j = (job *)arg;
    run(j);
    if (j->p->relay) {
        pool_lock(j->p);
        j->p->finished++;
        pthread_cond_signal(&j->p->cv);
        pool_unlock(j->p);
    }
    return NULL;
}

/* Starts workers for jobs[first..nthreads) with at least `stack` bytes
   of stack each (0: the platform's default); @return how many started. */
static int start_workers(pthread_t *tid, job *jobs, int first, int nthreads, size_t stack)
{
    pthread_attr_t attr;
    size_t have = 0;
    int k, use_attr = stack > 0 && pthread_attr_init(&attr) == 0;
    if (use_attr && (pthread_attr_getstacksize(&attr, &have) != 0 || have < stack) &&
        pthread_attr_setstacksize(&attr, stack) != 0) {
        pthread_attr_destroy(&attr);
        use_attr = 0; /* (the default, then: as before) */
    }
    for (k = first; k < nthreads; k++)
        if (pthread_create(&tid[k], use_attr ? &attr : NULL, thread_main, &jobs[k]) != 0)
            break; /* fewer threads: the rows still all get done */
    if (use_attr)
        pthread_attr_destroy(&attr);
    return k - first;
}
#endif

int rtpi_parallel_rows(int nrows, int nthreads, void *const *ctx,
                       rtpi_row_fn fn, void (*progress)(void *, double),
                       void *progress_user)
{
    return rtpi_parallel_rows_cancel(nrows, nthreads, ctx, fn, progress, NULL, progress_user, 0);
}

int rtpi_parallel_rows_stack(int nrows, int nthreads, void *const *ctx, rtpi_row_fn fn,
                             void (*progress)(void *, double), void *progress_user,
                             size_t stack)
{
    return rtpi_parallel_rows_cancel(nrows, nthreads, ctx, fn, progress, NULL, progress_user,
                                     stack);
}

int rtpi_parallel_rows_cancel(int nrows, int nthreads, void *const *ctx, rtpi_row_fn fn,
                              void (*progress)(void *, double), int (*cancel)(void *),
                              void *user, size_t stack)
{
    pool p;
    job jobs[RTPI_MAX_THREADS];
    int i;
    memset(&p, 0, sizeof p);
    p.nrows = nrows;
    p.fn = fn;
    p.ctx = ctx;
    p.progress = progress;
    p.cancel = cancel;
    p.progress_user = user;
    if (nthreads < 1)
        nthreads = 1;
    if (nthreads > RTPI_MAX_THREADS)
        nthreads = RTPI_MAX_THREADS;
    for (i = 0; i < nthreads; i++) {
        jobs[i].p = &p;
        jobs[i].ctx = ctx[i];
        jobs[i].is_main = i == 0;
    }
#ifdef RTP_HAVE_THREADS
    if (stack > 0 && pthread_mutex_init(&p.lock, NULL) == 0) {
        p.locking = 1;
        /* Work that needs a deep stack (a ray tree of many levels) runs
           on workers of rtp's own with that stack, all of it: the
           calling thread's stack is the host's and may be small (a
           thread of 128 KiB on musl, 512 KiB on macOS).  The caller
           waits and relays the progress. */
        pthread_t tid[RTPI_MAX_THREADS];
        int started = 0, reported = -1;
        p.relayed = -1;
        if (pthread_cond_init(&p.cv, NULL) == 0) {
            p.relay = 1;
            for (i = 0; i < nthreads; i++)
                jobs[i].is_main = 0;
            started = start_workers(tid, jobs, 0, nthreads, stack);
            pool_lock(&p);
            while (p.finished < started) {
                if ((p.progress || p.cancel) && p.done != reported &&
                    worth_report(&p, p.done, reported)) {
                    int d = reported = p.relayed = p.done;
                    pool_unlock(&p);
                    if (p.progress)
                        p.progress(p.progress_user, (double)d / p.nrows);
                    poll_cancel(&p);
                    pool_lock(&p);
                    continue;
                }
                pthread_cond_wait(&p.cv, &p.lock);
            }
            pool_unlock(&p);
            for (i = 0; i < started; i++)
                pthread_join(tid[i], NULL);
            pthread_cond_destroy(&p.cv);
            p.relay = 0;
            if (started > 0 && p.progress && p.done != reported)
                p.progress(p.progress_user, (double)p.done / p.nrows);
        }
        jobs[0].is_main = 1;
        if (started == 0)
            run(&jobs[0]); /* no thread to be had: here, as before */
        pthread_mutex_destroy(&p.lock);
        return p.cancelled ? 2 : p.stop;
    }
    if (nthreads > 1 && pthread_mutex_init(&p.lock, NULL) == 0) {
        pthread_t tid[RTPI_MAX_THREADS];
        p.locking = 1;
        int started = 1 + start_workers(tid, jobs, 1, nthreads, 0);
        run(&jobs[0]);
        for (i = 1; i < started; i++)
            pthread_join(tid[i], NULL);
        /* the rows the workers ended after the calling thread's last
           report: a last one (a trace's progress stopped at 67%) */
        if (p.progress && p.reported != p.done)
            p.progress(p.progress_user, (double)p.done / p.nrows);
        pthread_mutex_destroy(&p.lock);
        return p.cancelled ? 2 : p.stop;
    }
#else
    (void)stack;
#endif
    run(&jobs[0]);
    return p.cancelled ? 2 : p.stop;
}

/* rtpi_parallel_rows_poll's scaling of the rows' progress. */
typedef struct poll_part {
    const rtpi_poll *p;
    double lo, span;
} poll_part;

static void poll_part_progress(void *user, double done)
{
    const poll_part *q = (const poll_part *)user;
    q->p->progress(q->p->user, q->lo + q->span * done);
}

static int poll_part_cancel(void *user)
{
    const poll_part *q = (const poll_part *)user;
    return q->p->cancel(q->p->user);
}

int rtpi_parallel_rows_poll(int nrows, int nthreads, void *const *ctx, rtpi_row_fn fn,
                            const rtpi_poll *poll, double lo, double span)
{
    poll_part q;
    if (!poll || (!poll->progress && !poll->cancel))
        return rtpi_parallel_rows(nrows, nthreads, ctx, fn, NULL, NULL);
    q.p = poll;
    q.lo = lo;
    q.span = span;
    return rtpi_parallel_rows_cancel(nrows, nthreads, ctx, fn,
                                     poll->progress ? poll_part_progress : NULL,
                                     poll->cancel ? poll_part_cancel : NULL, &q, 0);
}

int rtpi_poll_cancelled(const rtpi_poll *poll)
{
    return poll && poll->cancel && poll->cancel(poll->user) != 0;
}

int rtpi_stopper_init(rtpi_stopper *st, const rtpi_poll *poll, double lo, double span)
{
    st->poll = poll && (poll->progress || poll->cancel) ? poll : NULL;
    st->lo = lo;
    st->span = span;
    st->last = -1.0; /* (the last report's step, STOPPER_REPORTS a build) */
    st->stop = 0;
    if (!st->poll)
        return 0;
    return rtpi_mutex_init(&st->lock) == 0 ? 0 : -1;
}

void rtpi_stopper_destroy(rtpi_stopper *st)
{
    if (st->poll)
        rtpi_mutex_destroy(&st->lock);
}

/* A build's progress and cancel are called at most this many times (a
   step's rows another REPORTS): an item buffer asked every 256 of a
   million triangles called them 4,000 times. */
#define STOPPER_REPORTS 250

int rtpi_stopper_poll(rtpi_stopper *st, int is_main, double done)
{
    int stop;
    if (!st->poll)
        return 0;
    if (is_main) {
        /* (the build's share, [lo, lo + span] of it, in STOPPER_REPORTS
           steps: only at a new one, forward) */
        double at = st->lo + st->span * (done < 1.0 ? done : 1.0);
        if (!(at * STOPPER_REPORTS >= st->last + 1.0))
            goto read;
        st->last = floor(at * STOPPER_REPORTS);
        if (st->poll->progress)
            st->poll->progress(st->poll->user, at);
        if (rtpi_poll_cancelled(st->poll)) {
            rtpi_mutex_lock(&st->lock);
            st->stop = 1;
            rtpi_mutex_unlock(&st->lock);
        }
    }
read:
    rtpi_mutex_lock(&st->lock);
    stop = st->stop;
    rtpi_mutex_unlock(&st->lock);
    return stop;
}
