/* parallel.c — rows of an image over POSIX threads (or the calling thread
 * alone when built with THREADS=0).  Rows are handed out one at a time, so
 * the result never depends on the number of threads. */
#include "internal.h"

#ifdef RTP_HAVE_THREADS
#include <pthread.h>
#endif

typedef struct pool {
    int nrows, next, done, stop;
    rtpi_row_fn fn;
    void *const *ctx;
    void (*progress)(void *user, double done);
    void *progress_user;
#ifdef RTP_HAVE_THREADS
    pthread_mutex_t lock;
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
    pthread_mutex_lock(&p->lock);
#else
    (void)p;
#endif
}

static void pool_unlock(pool *p)
{
#ifdef RTP_HAVE_THREADS
    pthread_mutex_unlock(&p->lock);
#else
    (void)p;
#endif
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
        pool_unlock(p);
        if (j->is_main && p->progress)
            p->progress(p->progress_user, (double)done / p->nrows);
    }
}

#ifdef RTP_HAVE_THREADS
static void *thread_main(void *arg)
{
    run((job *)arg);
    return NULL;
}
#endif

int rtpi_parallel_rows(int nrows, int nthreads, void *const *ctx,
                       rtpi_row_fn fn, void (*progress)(void *, double),
                       void *progress_user)
{
    pool p;
    job jobs[RTPI_MAX_THREADS];
    int i;
    memset(&p, 0, sizeof p);
    p.nrows = nrows;
    p.fn = fn;
    p.ctx = ctx;
    p.progress = progress;
    p.progress_user = progress_user;
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
    if (nthreads > 1) {
        pthread_t tid[RTPI_MAX_THREADS];
        int started;
        pthread_mutex_init(&p.lock, NULL);
        for (started = 1; started < nthreads; started++)
            if (pthread_create(&tid[started], NULL, thread_main, &jobs[started]) != 0)
                break; /* fewer threads: the rows still all get done */
        run(&jobs[0]);
        for (i = 1; i < started; i++)
            pthread_join(tid[i], NULL);
        pthread_mutex_destroy(&p.lock);
        return p.stop;
    }
#endif
    run(&jobs[0]);
    return p.stop;
}
