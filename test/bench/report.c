/* report.c — the error-against-run-time report of `make bench`.
 *
 *     build/bench/report MATRIX.TSV OUTDIR
 *
 * Reads the records test/bench/matrix.sh collected (tab separated: kind, scene,
 * edit, method, JSON from rtp's --stats) and writes OUTDIR/report.md (a
 * markdown table per scene, edit and method, and a summary per method) and
 * OUTDIR/errspeed.svg (RMSE against speed-up, both logarithmic, one series
 * per method; error-free points on an "exact" band below the axis).  Not a
 * benchmark itself: test/bench/run.sh runs only bench_* programs. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { F_KIND, F_SCENE, F_EDIT, F_METHOD, F_JSON, NFIELD };

typedef struct {
    char *f[NFIELD]; /* pointers into one allocation */
} record;

typedef struct {
    record *r;
    size_t n, cap;
} records;

/* one measured row of the table */
typedef struct {
    const char *scene, *edit, *method, *series;
    double seconds, ref_seconds, speedup, rmse, psnr, above, bpn, file_bytes, peak_kb;
    int has_seconds, has_speedup, own_ref, has_err, psnr_inf, has_above, vs_exact, has_bpn,
        has_file, has_peak, failed;
} row;

/* -------------------------------------------------------------- input */

static char *read_line(FILE *f)
{
    size_t cap = 1024, len = 0;
    char *buf = (char *)malloc(cap);
    int c;
    if (!buf)
        return NULL;
    while ((c = getc(f)) != EOF && c != '\n') {
        if (len + 2 > cap) {
            char *nb = (char *)realloc(buf, cap * 2);
            if (!nb) {
                free(buf);
                return NULL;
            }
            buf = nb;
            cap *= 2;
        }
        buf[len++] = (char)c;
    }
    if (c == EOF && len == 0) {
        free(buf);
        return NULL;
    }
    if (len > 0 && buf[len - 1] == '\r')
        len--;
    buf[len] = '\0';
    return buf;
}

static int load(const char *path, records *rs)
{
    FILE *f = fopen(path, "r");
    char *line;
    if (!f) {
        perror(path);
        return -1;
    }
    while ((line = read_line(f)) != NULL) {
        record r;
        int k;
        char *p = line;
        for (k = 0; k < NFIELD; k++) {
            char *tab;
            r.f[k] = p;
            if (k == NFIELD - 1)
                break;
            tab = strchr(p, '\t');
            if (tab) {
                *tab = '\0';
                p = tab + 1;
            } else {
                p = line + strlen(line); /* missing fields are empty */
            }
        }
        if (rs->n == rs->cap) {
            size_t nc = rs->cap ? rs->cap * 2 : 64;
            record *nr = (record *)realloc(rs->r, nc * sizeof *nr);
            if (!nr) {
                free(line);
                fclose(f);
                return -1;
            }
            rs->r = nr;
            rs->cap = nc;
        }
        rs->r[rs->n++] = r;
    }
    fclose(f);
    return 0;
}

/* A number from a one-line JSON object: 1 found, 2 the string "inf",
 * 0 absent or not a number. */
static int jnum(const char *json, const char *key, double *v)
{
    char pat[80];
    const char *p;
    char *end;
    if (!json || strlen(key) > 70)
        return 0;
    sprintf(pat, "\"%s\":", key);
    p = strstr(json, pat);
    if (!p)
        return 0;
    p += strlen(pat);
    while (*p == ' ')
        p++;
    if (strncmp(p, "\"inf\"", 5) == 0) {
        *v = HUGE_VAL;
        return 2;
    }
    *v = strtod(p, &end);
    return end != p;
}

static const record *find(const records *rs, const char *kind, const char *scene,
                          const char *edit, const char *method)
{
    size_t i;
    for (i = 0; i < rs->n; i++) {
        const record *r = &rs->r[i];
        if (strcmp(r->f[F_KIND], kind) == 0 && (!scene || strcmp(r->f[F_SCENE], scene) == 0) &&
            (!edit || strcmp(r->f[F_EDIT], edit) == 0) &&
            (!method || strcmp(r->f[F_METHOD], method) == 0))
            return r;
    }
    return NULL;
}

static const char *meta(const records *rs, const char *key)
{
    const record *r = find(rs, "meta", key, NULL, NULL);
    return r ? r->f[F_EDIT] : NULL;
}

/* ------------------------------------------------------------- series */

#define MAX_SERIES 32
typedef struct {
    char name[64];
    const char *color;
    int marker; /* 0 circle 1 square 2 triangle 3 diamond 4 cross 5 plus 6 down-triangle */
} series;

static series ser[MAX_SERIES];
static int nser;

static int resolution_rank(const char *method)
{
    const char *c = strchr(method, ':');
    int r = c ? atoi(c + 1) : 0;
    return r <= 256 ? 0 : r <= 512 ? 1 : r <= 1024 ? 2 : 3;
}

static int series_index(const char *name)
{
    static const char *const blues[] = {"#6baed6", "#3182bd", "#08519c", "#08306b"};
    static const char *const reds[] = {"#fd8d3c", "#e6550d", "#a63603", "#67000d"};
    static const char *const greens[] = {"#74c476", "#31a354", "#006d2c", "#00441b"};
    static const char *const others[] = {"#e7298a", "#66a61e", "#e6ab02", "#1b9e77"};
    int i;
    series *s;
    for (i = 0; i < nser; i++)
        if (strcmp(ser[i].name, name) == 0)
            return i;
    if (nser == MAX_SERIES)
        return MAX_SERIES - 1;
    s = &ser[nser];
    strncpy(s->name, name, sizeof s->name - 1);
    s->name[sizeof s->name - 1] = '\0';
    if (strcmp(name, "optical edits") == 0) {
        s->color = "#555555";
        s->marker = 5;
    } else if (strcmp(name, "first evaluation") == 0) {
        s->color = "#7b3294";
        s->marker = 6;
    } else if (strcmp(name, "exact") == 0) {
        s->color = "#000000";
        s->marker = 4;
    } else if (strncmp(name, "lightbuf", 8) == 0) {
        s->color = blues[resolution_rank(name)];
        s->marker = resolution_rank(name);
    } else if (strncmp(name, "itembuf", 7) == 0) {
        s->color = reds[resolution_rank(name)];
        s->marker = resolution_rank(name);
    } else if (strncmp(name, "osmesa", 6) == 0) {
        s->color = greens[resolution_rank(name)];
        s->marker = resolution_rank(name);
    } else {
        s->color = others[nser % 4];
        s->marker = nser % 4;
    }
    return nser++;
}

static const char *series_label(const char *name, char *buf, size_t n)
{
    if (strcmp(name, "exact") == 0)
        snprintf(buf, n, "moved light: exact (shadow rays)");
    else if (strcmp(name, "optical edits") == 0)
        snprintf(buf, n, "optical edits (trees only)");
    else if (strcmp(name, "first evaluation") == 0)
        snprintf(buf, n, "first evaluation (cold caches)");
    else
        snprintf(buf, n, "moved light: %s", name);
    return buf;
}

/* -------------------------------------------------------------- rows */

static void make_row(const records *rs, const record *r, row *w)
{
    const char *j = r->f[F_JSON];
    const record *ex, *d, *tr;
    double v;
    int k;
    memset(w, 0, sizeof *w);
    w->scene = r->f[F_SCENE];
    w->edit = r->f[F_EDIT];
    w->method = r->f[F_METHOD];
    if (strcmp(w->edit, "first evaluation (builds caches)") == 0)
        w->series = "first evaluation";
    else if (strcmp(w->edit, "moved light") == 0)
        w->series = w->method;
    else
        w->series = "optical edits";
    if (strcmp(r->f[F_KIND], "trace") == 0)
        w->series = NULL;
    if (strncmp(j, "{", 1) != 0) {
        w->failed = 1;
    } else {
        w->has_seconds = jnum(j, "seconds", &w->seconds) == 1;
        w->has_peak = jnum(j, "peak_rss_kb", &w->peak_kb) == 1;
        w->has_bpn = jnum(j, "bytes_per_node", &w->bpn) == 1;
        w->has_file = jnum(j, "file_bytes", &w->file_bytes) == 1;
        if (jnum(j, "reference_seconds", &v) == 1) {
            w->ref_seconds = v;
            w->has_speedup = 1;
            w->own_ref = 1;
            k = jnum(j, "rmse", &w->rmse);
            w->has_err = k == 1;
            k = jnum(j, "psnr", &w->psnr);
            w->psnr_inf = k == 2;
        } else if (strcmp(r->f[F_KIND], "reeval") == 0) {
            /* same edit state as the exact run: its reference time */
            ex = find(rs, "reeval", w->scene, w->edit, "exact");
            if (ex && jnum(ex->f[F_JSON], "reference_seconds", &v) == 1) {
                w->ref_seconds = v;
                w->has_speedup = 1;
            }
            d = find(rs, "diff", w->scene, w->edit, w->method);
            if (d) {
                w->vs_exact = 1;
                w->has_err = jnum(d->f[F_JSON], "rmse", &w->rmse) == 1;
                w->psnr_inf = jnum(d->f[F_JSON], "psnr", &w->psnr) == 2;
                w->has_above = jnum(d->f[F_JSON], "above", &w->above) == 1;
            }
        }
        if (w->has_speedup)
            w->has_speedup = w->has_seconds && w->seconds > 0.0;
        if (w->has_speedup)
            w->speedup = w->ref_seconds / w->seconds;
    }
    tr = find(rs, "trace", w->scene, NULL, NULL);
    if (tr && !w->has_bpn)
        w->has_bpn = jnum(tr->f[F_JSON], "bytes_per_node", &w->bpn) == 1;
    if (tr && !w->has_file)
        w->has_file = jnum(tr->f[F_JSON], "file_bytes", &w->file_bytes) == 1;
}

static void md_row(FILE *o, const row *w, int is_trace)
{
    fprintf(o, "| %s | %s | %s | ", w->scene, w->edit,
            is_trace ? "full trace -o (reference)"
            : strcmp(w->series ? w->series : "", "exact") == 0 ? "exact (shadow rays)"
            : strcmp(w->edit, "moved light") == 0                ? w->method
                                                                 : "trees");
    if (w->failed) {
        fputs("n/a | n/a | n/a | n/a | n/a |", o);
    } else {
        if (w->has_seconds)
            fprintf(o, "%.4f | ", w->seconds);
        else
            fputs("n/a | ", o);
        if (is_trace)
            fputs("1 | ", o);
        else if (w->has_speedup)
            fprintf(o, "%.1f | ", w->speedup);
        else
            fputs("n/a | ", o);
        if (is_trace)
            fputs("— | — | ", o);
        else if (w->has_err) {
            if (w->rmse == 0.0)
                fputs("0 | ", o);
            else
                fprintf(o, "%.3g%s | ", w->rmse, w->vs_exact ? "¹" : "");
            if (w->psnr_inf || w->rmse == 0.0)
                fputs("inf | ", o);
            else
                fprintf(o, "%.1f | ", w->psnr);
        } else
            fputs("n/a | n/a | ", o);
        if (w->has_above)
            fprintf(o, "%.3f%% |", 100.0 * w->above);
        else
            fputs("— |", o);
    }
    if (w->has_bpn)
        fprintf(o, " %.0f |", w->bpn);
    else
        fputs(" — |", o);
    if (w->has_file)
        fprintf(o, " %.2f |", w->file_bytes / 1048576.0);
    else
        fputs(" — |", o);
    if (w->has_peak && !w->failed)
        fprintf(o, " %.0f%s |\n", w->peak_kb / 1024.0,
                w->own_ref ? "²" : "");
    else
        fputs(" n/a |\n", o);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* --------------------------------------------------------------- SVG */

static void xml_text(FILE *o, const char *s)
{
    for (; *s; s++) {
        if (*s == '&')
            fputs("&amp;", o);
        else if (*s == '<')
            fputs("&lt;", o);
        else if (*s == '>')
            fputs("&gt;", o);
        else if (*s == '"')
            fputs("&quot;", o);
        else
            fputc(*s, o);
    }
}

static void marker(FILE *o, int m, double x, double y, const char *color)
{
    const double r = 4.5;
    switch (m) {
    case 0:
        fprintf(o, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"%.1f\" fill=\"%s\"/>\n", x, y, r, color);
        break;
    case 1:
        fprintf(o, "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"%s\"/>\n",
                x - r * 0.85, y - r * 0.85, 1.7 * r, 1.7 * r, color);
        break;
    case 2:
        fprintf(o, "<polygon points=\"%.1f,%.1f %.1f,%.1f %.1f,%.1f\" fill=\"%s\"/>\n", x,
                y - r * 1.15, x - r, y + r * 0.75, x + r, y + r * 0.75, color);
        break;
    case 3:
        fprintf(o, "<polygon points=\"%.1f,%.1f %.1f,%.1f %.1f,%.1f %.1f,%.1f\" fill=\"%s\"/>\n",
                x, y - r * 1.2, x + r, y, x, y + r * 1.2, x - r, y, color);
        break;
    case 4:
        fprintf(o,
                "<path d=\"M%.1f,%.1fL%.1f,%.1fM%.1f,%.1fL%.1f,%.1f\" stroke=\"%s\" "
                "stroke-width=\"2\" fill=\"none\"/>\n",
                x - r, y - r, x + r, y + r, x - r, y + r, x + r, y - r, color);
        break;
    case 5:
        fprintf(o,
                "<path d=\"M%.1f,%.1fL%.1f,%.1fM%.1f,%.1fL%.1f,%.1f\" stroke=\"%s\" "
                "stroke-width=\"2\" fill=\"none\"/>\n",
                x - r, y, x + r, y, x, y - r, x, y + r, color);
        break;
    default:
        fprintf(o, "<polygon points=\"%.1f,%.1f %.1f,%.1f %.1f,%.1f\" fill=\"%s\"/>\n", x,
                y + r * 1.15, x - r, y - r * 0.75, x + r, y - r * 0.75, color);
        break;
    }
}

/* "10^k" with a raised exponent, or a plain number for 0.01 .. 1000 */
static void decade_label(FILE *o, double x, double y, const char *anchor, int k, int plain)
{
    fprintf(o, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"%s\">", x, y, anchor);
    if (plain && k >= -2 && k <= 3) {
        static const char *const v[] = {"0.01", "0.1", "1", "10", "100", "1000"};
        fputs(v[k + 2], o);
    } else {
        fprintf(o, "10<tspan dy=\"-6\" font-size=\"9\">%d</tspan>", k);
    }
    fputs("</text>\n", o);
}

static int write_svg(const char *path, const row *rows, size_t nrows, const records *rs)
{
    const double W = 960, H = 620, L = 80, R = 270, T = 64, B = 66;
    double px0 = L, px1 = W - R, py0 = T, py1;
    double xmin = HUGE_VAL, xmax = 0, ymin = HUGE_VAL, ymax = 0;
    int xlo, xhi, ylo, yhi, k, s, nexact_lanes = 0, lane_of[MAX_SERIES];
    double band_top, band_h, lane_h = 9.0;
    size_t i;
    char lab[128];
    const char *scn = meta(rs, "scenes"), *mach = meta(rs, "machine"),
               *thr = meta(rs, "threads");
    FILE *o = fopen(path, "w");
    if (!o) {
        perror(path);
        return -1;
    }
    for (s = 0; s < MAX_SERIES; s++)
        lane_of[s] = -1;
    for (i = 0; i < nrows; i++) {
        const row *w = &rows[i];
        if (!w->series || !w->has_speedup || !w->has_err || w->speedup <= 0)
            continue;
        s = series_index(w->series);
        if (w->speedup < xmin)
            xmin = w->speedup;
        if (w->speedup > xmax)
            xmax = w->speedup;
        if (w->rmse > 0) {
            if (w->rmse < ymin)
                ymin = w->rmse;
            if (w->rmse > ymax)
                ymax = w->rmse;
        } else if (lane_of[s] < 0) {
            lane_of[s] = 1;
        }
    }
    /* lanes of the exact band in series order */
    for (s = 0; s < nser; s++)
        if (lane_of[s] > 0)
            lane_of[s] = nexact_lanes++;
    if (!(xmax > 0)) {
        xmin = 1;
        xmax = 10;
    }
    if (!(ymax > 0)) {
        ymin = 1e-4;
        ymax = 1e-1;
    }
    xlo = (int)floor(log10(xmin));
    xhi = (int)ceil(log10(xmax));
    if (xhi <= xlo)
        xhi = xlo + 1;
    if (xlo > 0)
        xlo = 0; /* keep the break-even line in view */
    ylo = (int)floor(log10(ymin));
    yhi = (int)ceil(log10(ymax));
    if (yhi <= ylo)
        yhi = ylo + 1;
    band_h = nexact_lanes > 0 ? 14.0 + lane_h * nexact_lanes : 0.0;
    py1 = H - B - band_h - (band_h > 0 ? 10.0 : 0.0);
    band_top = py1 + 10.0;

#define XP(v) (px0 + (px1 - px0) * (log10(v) - xlo) / (double)(xhi - xlo))
#define YP(v) (py1 - (py1 - py0) * (log10(v) - ylo) / (double)(yhi - ylo))

    fprintf(o, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
               "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%.0f\" height=\"%.0f\" "
               "viewBox=\"0 0 %.0f %.0f\" font-family=\"Helvetica, Arial, sans-serif\" "
               "font-size=\"12\">\n",
            W, H, W, H);
    fprintf(o, "<rect x=\"0\" y=\"0\" width=\"%.0f\" height=\"%.0f\" fill=\"#ffffff\"/>\n", W, H);
    fputs("<text x=\"20\" y=\"26\" font-size=\"17\" font-weight=\"bold\">rtp: error against "
          "speed-up of re-evaluation over a full trace</text>\n", o);
    fputs("<text x=\"20\" y=\"45\" font-size=\"11\" fill=\"#444444\">", o);
    if (scn)
        xml_text(o, scn);
    if (thr) {
        fputs("; -j ", o);
        xml_text(o, thr);
    }
    if (mach) {
        fputs("; ", o);
        xml_text(o, mach);
    }
    fputs("</text>\n", o);

    /* grid: minor, then major */
    fputs("<g stroke=\"#e6e6e6\" stroke-width=\"1\">\n", o);
    for (k = xlo; k < xhi; k++) {
        int m;
        for (m = 2; m <= 9; m++) {
            double x = XP(m * pow(10.0, k));
            fprintf(o, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\"/>\n", x, py0, x,
                    py1);
        }
    }
    for (k = ylo; k < yhi; k++) {
        int m;
        for (m = 2; m <= 9; m++) {
            double y = YP(m * pow(10.0, k));
            fprintf(o, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\"/>\n", px0, y, px1,
                    y);
        }
    }
    fputs("</g>\n<g stroke=\"#bdbdbd\" stroke-width=\"1\">\n", o);
    for (k = xlo; k <= xhi; k++) {
        double x = XP(pow(10.0, k));
        fprintf(o, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\"/>\n", x, py0, x,
                band_h > 0 ? band_top + band_h : py1);
    }
    for (k = ylo; k <= yhi; k++) {
        double y = YP(pow(10.0, k));
        fprintf(o, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\"/>\n", px0, y, px1, y);
    }
    fputs("</g>\n", o);

    /* break-even: speed-up 1 */
    if (xlo <= 0 && xhi >= 0) {
        double x = XP(1.0);
        fprintf(o,
                "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#999999\" "
                "stroke-dasharray=\"5,4\"/>\n"
                "<text x=\"%.1f\" y=\"%.1f\" font-size=\"10\" fill=\"#777777\" "
                "transform=\"rotate(-90 %.1f %.1f)\">slower than a full trace</text>\n",
                x, py0, x, band_h > 0 ? band_top + band_h : py1, x - 5, py0 + 150, x - 5,
                py0 + 150);
    }

    /* the exact band */
    if (band_h > 0) {
        fprintf(o,
                "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"#f4f8ee\" "
                "stroke=\"#9ab973\"/>\n",
                px0, band_top, px1 - px0, band_h);
        fprintf(o,
                "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\" fill=\"#4d7a1f\">0 "
                "(exact)</text>\n",
                px0 - 6, band_top + band_h / 2 + 4);
    }

    /* axes, ticks, labels */
    fprintf(o,
            "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"none\" "
            "stroke=\"#333333\"/>\n",
            px0, py0, px1 - px0, py1 - py0);
    fputs("<g stroke=\"#333333\">\n", o);
    for (k = xlo; k <= xhi; k++) {
        int m;
        double x = XP(pow(10.0, k));
        fprintf(o, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\"/>\n", x, py1, x,
                py1 + 6);
        for (m = 2; m <= 9 && k < xhi; m++) {
            double xm = XP(m * pow(10.0, k));
            fprintf(o, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\"/>\n", xm, py1, xm,
                    py1 + 3);
        }
    }
    for (k = ylo; k <= yhi; k++) {
        int m;
        double y = YP(pow(10.0, k));
        fprintf(o, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\"/>\n", px0 - 6, y, px0,
                y);
        for (m = 2; m <= 9 && k < yhi; m++) {
            double ym = YP(m * pow(10.0, k));
            fprintf(o, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\"/>\n", px0 - 3, ym,
                    px0, ym);
        }
    }
    fputs("</g>\n", o);
    {
        double yl = (band_h > 0 ? band_top + band_h : py1) + 18;
        for (k = xlo; k <= xhi; k++)
            decade_label(o, XP(pow(10.0, k)), yl, "middle", k, 1);
        for (k = ylo; k <= yhi; k++)
            decade_label(o, px0 - 9, YP(pow(10.0, k)) + 4, "end", k, 0);
        fprintf(o,
                "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\" font-size=\"13\">speed-up "
                "over a full trace at the same thread count (log)</text>\n",
                (px0 + px1) / 2, yl + 24);
        fprintf(o,
                "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\" font-size=\"13\" "
                "transform=\"rotate(-90 %.1f %.1f)\">RMSE against a full trace (log)</text>\n",
                24.0, (py0 + py1) / 2, 24.0, (py0 + py1) / 2);
    }

    /* the points, series by series so that each is one group */
    for (s = 0; s < nser; s++) {
        fprintf(o, "<g opacity=\"0.85\"><title>");
        xml_text(o, series_label(ser[s].name, lab, sizeof lab));
        fputs("</title>\n", o);
        for (i = 0; i < nrows; i++) {
            const row *w = &rows[i];
            double x, y;
            if (!w->series || strcmp(w->series, ser[s].name) != 0 || !w->has_speedup ||
                !w->has_err || w->speedup <= 0)
                continue;
            x = XP(w->speedup);
            y = w->rmse > 0 ? YP(w->rmse) : band_top + 10.0 + lane_h * lane_of[s];
            marker(o, ser[s].marker, x, y, ser[s].color);
        }
        fputs("</g>\n", o);
    }

    /* legend */
    {
        double lx = px1 + 18, ly = py0 + 4;
        fprintf(o,
                "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"#ffffff\" "
                "stroke=\"#bbbbbb\"/>\n",
                lx - 8, ly - 4, W - lx - 4, 30.0 + 18.0 * nser + 52);
        fprintf(o, "<text x=\"%.1f\" y=\"%.1f\" font-weight=\"bold\">method</text>\n", lx,
                ly + 12);
        for (s = 0; s < nser; s++) {
            double y = ly + 32 + 18.0 * s;
            marker(o, ser[s].marker, lx + 6, y - 4, ser[s].color);
            fprintf(o, "<text x=\"%.1f\" y=\"%.1f\" font-size=\"11\">", lx + 18, y);
            xml_text(o, series_label(ser[s].name, lab, sizeof lab));
            fputs("</text>\n", o);
        }
        fprintf(o,
                "<text x=\"%.1f\" y=\"%.1f\" font-size=\"10\" fill=\"#555555\">one point per "
                "scene and edit;</text>\n"
                "<text x=\"%.1f\" y=\"%.1f\" font-size=\"10\" fill=\"#555555\">RMSE 0 is "
                "drawn on the exact band,</text>\n"
                "<text x=\"%.1f\" y=\"%.1f\" font-size=\"10\" fill=\"#555555\">one lane per "
                "method</text>\n",
                lx, ly + 36 + 18.0 * nser, lx, ly + 50 + 18.0 * nser, lx,
                ly + 64 + 18.0 * nser);
    }
    fputs("</svg>\n", o);
#undef XP
#undef YP
    if (fclose(o) != 0) {
        perror(path);
        return -1;
    }
    return 0;
}

/* ------------------------------------------------------------ report */

static int write_md(const char *path, const row *rows, size_t nrows, const records *rs)
{
    FILE *o = fopen(path, "w");
    size_t i, n;
    int s;
    const char *v;
    double *sp;
    if (!o) {
        perror(path);
        return -1;
    }
    sp = (double *)malloc((nrows + 1) * sizeof *sp);
    if (!sp) {
        fclose(o);
        return -1;
    }
    fputs("## Error against run time\n\n", o);
    if ((v = meta(rs, "machine")) != NULL)
        fprintf(o, "- machine: %s\n", v);
    if ((v = meta(rs, "compiler")) != NULL)
        fprintf(o, "- compiler: %s\n", v);
    if ((v = meta(rs, "flags")) != NULL)
        fprintf(o, "- flags: `%s`\n", v);
    if ((v = meta(rs, "rtp")) != NULL)
        fprintf(o, "- %s\n", v);
    if ((v = meta(rs, "scenes")) != NULL)
        fprintf(o, "- scenes: %s\n", v);
    if ((v = meta(rs, "threads")) != NULL)
        fprintf(o, "- threads: -j %s for every re-evaluation and every full trace\n", v);
    if ((v = meta(rs, "date")) != NULL)
        fprintf(o, "- run: %s", v);
    if ((v = meta(rs, "matrix_seconds")) != NULL)
        fprintf(o, ", matrix %s s wall", v);
    fputs("\n", o);
    for (i = 0; i < rs->n; i++)
        if (strcmp(rs->r[i].f[F_KIND], "note") == 0)
            fprintf(o, "- note (%s): %s\n", rs->r[i].f[F_SCENE], rs->r[i].f[F_EDIT]);
    fputs("\nHow it was measured: `rtp trace -o` writes each scene's tree; one `rtp reeval "
          "--stream --reference` then applies the edits in the order shown (edits persist), "
          "timing each on **warm caches** (the first, empty line builds them and is listed as "
          "*first evaluation*) and tracing the same edited scene in full for its time and "
          "error. *seconds* is the re-evaluation alone (tree already loaded); *speed-up* is "
          "that full trace's time over it. The other shadow modes replay the same edits "
          "without `--reference`; only their moved-light line differs, so its image is "
          "compared with the exact mode's (which the reference showed equal to a full trace) "
          "and its speed-up uses the exact run's reference time. The moved light is light 0 "
          "shifted by a tenth of its distance from the origin.\n\n", o);
    fputs("![error against speed-up](errspeed.svg)\n\n", o);
    fputs("| scene | edit | method | seconds | speed-up | RMSE | PSNR dB | pixels >1/255 vs "
          "exact | B/node | file MiB | peak MiB |\n",
          o);
    fputs("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n", o);
    for (i = 0; i < nrows; i++)
        md_row(o, &rows[i], rows[i].series == NULL);
    fputs("\n¹ against the exact mode's image of the same edit (equal to a full trace where "
          "that row's RMSE is 0).  ² the process's peak RSS includes the `--reference` full "
          "trace; rows without ² are the re-evaluating process alone.  *pixels >1/255 vs "
          "exact* (`rtp diff --threshold 1/255`, `above`) stands in for the wrong-shadow "
          "share: the JSON gives no per-node decision count, so this is the share of pixels "
          "whose value differs from the exact mode's by more than 1/255.  *first evaluation* "
          "is the cost a session pays once; every edit after it is warm.  The full trace "
          "row's seconds include writing the tree file.\n\n",
          o);

    /* summary per method */
    fputs("### Summary per method\n\n| method | points | median speed-up | min–max speed-up "
          "| max RMSE | min PSNR dB | mean pixels >1/255 |\n|---|---:|---:|---:|---:|---:|---:|\n",
          o);
    for (s = 0; s < nser; s++) {
        double maxe = 0, minp = HUGE_VAL, above = 0;
        int nabove = 0, anyerr = 0;
        char lab[128];
        n = 0;
        for (i = 0; i < nrows; i++) {
            const row *w = &rows[i];
            if (!w->series || strcmp(w->series, ser[s].name) != 0 || w->failed)
                continue;
            if (w->has_speedup)
                sp[n++] = w->speedup;
            if (w->has_err) {
                anyerr = 1;
                if (w->rmse > maxe)
                    maxe = w->rmse;
                if (!w->psnr_inf && w->rmse > 0 && w->psnr < minp)
                    minp = w->psnr;
            }
            if (w->has_above) {
                above += w->above;
                nabove++;
            }
        }
        fprintf(o, "| %s | %lu | ", series_label(ser[s].name, lab, sizeof lab),
                (unsigned long)n);
        if (n > 0) {
            qsort(sp, n, sizeof *sp, cmp_double);
            fprintf(o, "%.1f | %.1f–%.1f | ",
                    n % 2 ? sp[n / 2] : 0.5 * (sp[n / 2 - 1] + sp[n / 2]), sp[0], sp[n - 1]);
        } else {
            fputs("n/a | n/a | ", o);
        }
        if (!anyerr)
            fputs("n/a | n/a | ", o);
        else if (maxe == 0)
            fputs("0 | inf | ", o);
        else
            fprintf(o, "%.3g | %.1f | ", maxe, minp);
        if (nabove)
            fprintf(o, "%.3f%% |\n", 100.0 * above / nabove);
        else
            fputs("— |\n", o);
    }
    free(sp);
    if (fclose(o) != 0) {
        perror(path);
        return -1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    records rs = {NULL, 0, 0};
    row *rows;
    size_t i, n = 0;
    char md[4096], svg[4096];
    int rc = 0;
    if (argc != 3) {
        fputs("usage: report MATRIX.TSV OUTDIR\n", stderr);
        return 2;
    }
    if (strlen(argv[2]) > 4000 || load(argv[1], &rs) != 0)
        return 1;
    rows = (row *)calloc(rs.n + 1, sizeof *rows);
    if (!rows)
        return 1;
    for (i = 0; i < rs.n; i++) {
        const char *k = rs.r[i].f[F_KIND];
        if (strcmp(k, "trace") == 0 || strcmp(k, "reeval") == 0) {
            make_row(&rs, &rs.r[i], &rows[n]);
            if (rows[n].series)
                series_index(rows[n].series);
            n++;
        }
    }
    sprintf(md, "%s/report.md", argv[2]);
    sprintf(svg, "%s/errspeed.svg", argv[2]);
    if (write_svg(svg, rows, n, &rs) != 0 || write_md(md, rows, n, &rs) != 0)
        rc = 1;
    for (i = 0; i < rs.n; i++)
        free(rs.r[i].f[0]);
    free(rs.r);
    free(rows);
    return rc;
}
