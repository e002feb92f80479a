/* test_obj.c — the OBJ/MTL reader: every face form, negative indices,
 * polygons, materials, transforms, broken inputs, truncation, and the
 * shared meshes when ../shared is present. */
#include "check.h"
#include "readers.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static rtp_status load(const char *text, const char *name, rtp_scene **s,
                       rtp_error *err)
{
    return rtp_scene_load_memory(text, strlen(text), name, "obj", NULL, s, err);
}

static int near(double a, double b, double tol) { return fabs(a - b) <= tol; }

static rtpi_v3 tri_normal(const rtp_scene *s, const rtpi_tri *t)
{
    rtpi_v3 p0 = v3_from_f(s->pos + 3 * (size_t)t->v[0]);
    rtpi_v3 p1 = v3_from_f(s->pos + 3 * (size_t)t->v[1]);
    rtpi_v3 p2 = v3_from_f(s->pos + 3 * (size_t)t->v[2]);
    return v3_cross(v3_sub(p1, p0), v3_sub(p2, p0));
}

static void test_faces(void)
{
    rtp_scene *s = NULL;
    rtp_error err;
    const char *text =
        "# all face forms\no thing\ng group\ns 1\n"
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 1.0\n"
        "vt 0 0\nvt 1 0 0\nvt 1 1\nvt 0.5\n"
        "vn 0 0 2\n"
        "f 1 2 3\n"
        "f 1/1 2/2 3/3\n"
        "f 1//1 2//1 3//1\n"
        "f 1/1/1 2/2/1 3/3/1\n"
        "f -4 -3 -2 -1\n"            /* negative: the last four vertices */
        "f -4/-4/-1 -3/-3/-1 -2/-2/-1\n"
        "s off\nusemtl_unknown_is_not_a_keyword_but_this_line_is_skipped_by_g\n";
    /* that last line is not valid OBJ: test it separately below */
    const char *ok_text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 1.0\n"
                          "vt 0 0\nvt 1 0 0\nvt 1 1\nvt 0.5\nvn 0 0 2\n"
                          "o a\ng b c\ns 1\nl 1 2\nl 1/1 2/2 -1/-1\np 1 -1\ns off\ns 0\n"
                          "s 4294967295\ns 99999999999999999999\ns +2\n"
                          "s on\ns 12\n"
                          "f 1 2 3\nf 1/1 2/2 3/3\nf 1//1 2//1 3//1\nf 1/1/1 2/2/1 3/3/1\n"
                          "f -4 -3 -2 -1\nf -4/-4/-1 -3/-3/-1 -2/-2/-1\n";
    CHECK(load(text, "f.obj", &s, &err) == RTP_ERR_PARSE);
    CHECK(err.line == 21 && err.column == 1);
    rtp_scene_destroy(s);
    s = NULL;
    CHECK(load(ok_text, "f.obj", &s, &err) == RTP_OK);
    if (!s)
        return;
    CHECK(s->npos == 4 && s->nuv == 4 && s->nnrm == 1);
    CHECK(s->ntris == 7);
    CHECK(s->tris[0].t[0] == RTPI_NONE && s->tris[0].n[0] == RTPI_NONE);
    CHECK(s->tris[1].t[2] == 2 && s->tris[1].n[0] == RTPI_NONE);
    CHECK(s->tris[2].t[0] == RTPI_NONE && s->tris[2].n[1] == 0);
    CHECK(s->tris[3].t[1] == 1 && s->tris[3].n[2] == 0);
    CHECK(s->nrm[2] == 1.0f); /* normalised */
    CHECK(s->uv[7] == 0.0f && s->uv[6] == 0.5f); /* vt u alone: v = 0 */
    /* the quad from negative indices: two triangles, area 1, facing +z */
    CHECK(near(0.5 * (v3_len(tri_normal(s, &s->tris[4])) + v3_len(tri_normal(s, &s->tris[5]))),
               1.0, 1e-6));
    CHECK(tri_normal(s, &s->tris[4]).z > 0 && tri_normal(s, &s->tris[5]).z > 0);
    CHECK(s->tris[6].v[0] == 0 && s->tris[6].t[0] == 0 && s->tris[6].n[0] == 0);
    /* no usemtl: one default material */
    CHECK(s->nmats == 1 && s->tris[0].mat == 0);
    rtp_scene_destroy(s);
}

/* A concave n-gon and a face whose indices are relative to a vertex list
   that keeps growing. */
/* A vn 1e-200 times a direction (its square underflows) is that
   direction: the face stays smooth, not flat for a zero normal. */
static void test_tiny_normal(void)
{
    rtp_scene *s = NULL;
    rtp_error err;
    const char *text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn -1e-200 -2e-200 2e-200\nvn 0 0 1\n"
                       "f 1//1 2//2 3//2\n";
    CHECK(load(text, "tiny.obj", &s, &err) == RTP_OK);
    if (!s)
        return;
    CHECK(s->ntris == 1 && s->nnrm == 2);
    if (s->ntris == 1 && s->nnrm == 2) {
        const float *n = s->nrm;
        CHECK(s->tris[0].n[0] != RTPI_NONE);
        CHECK_MSG(near(n[0], -1.0 / 3, 1e-7) && near(n[1], -2.0 / 3, 1e-7) &&
                      near(n[2], 2.0 / 3, 1e-7),
                  "%g %g %g", n[0], n[1], n[2]);
    }
    rtp_scene_destroy(s);
}

/* An OBJ and its MTL with classic Mac OS line ends ('\r' alone) read as
   with '\n': they were one line, refused at its second statement. */
static void test_cr_line_ends(void)
{
    rtp_scene *s = NULL;
    rtp_error err;
    const char *text = "# cr\rv 0 0 0\rv 1 0 0\rv 0 1 0\rvn 0 0 1\rf 1//1 2//1 3//1\r"
                       "f 1 2 \\\r3\r";
    CHECK(load(text, "cr.obj", &s, &err) == RTP_OK);
    if (s) {
        CHECK(s->npos == 3 && s->ntris == 2 && s->tris[0].n[0] != RTPI_NONE);
        rtp_scene_destroy(s);
    }
}

static void test_ngon(void)
{
    rtp_scene *s = NULL;
    rtp_error err;
    size_t faces = 0, i;
    double area = 0;
    const char *text = "v -2 -1 0\nv 1 -1 0\nv 1 0 0\nv -1 0 0\nv -1 2 0\nv -2 2 0\n"
                       "f 1 2 3 4 5 6\n"
                       "v 10 0 0\nv 11 0 0\nv 10 1 0\n"
                       "f -3 -2 -1\n";
    CHECK(rtpi_scene_create(NULL, &s) == RTP_OK);
    if (!s)
        return;
    CHECK(rtpi_read_obj_ex(s, text, strlen(text), "n.obj", NULL, RTPI_NONE, &faces, &err) ==
          RTP_OK);
    CHECK(faces == 2);
    CHECK(s->ntris == 5);
    for (i = 0; i < 4; i++) {
        rtpi_v3 n = tri_normal(s, &s->tris[i]);
        area += 0.5 * v3_len(n);
        CHECK(n.z > 0);
    }
    CHECK(near(area, 5.0, 1e-6));
    CHECK(s->tris[4].v[0] == 6 && s->tris[4].v[2] == 8);
    rtp_scene_destroy(s);
}

static void test_xform(void)
{
    rtp_scene *s = NULL;
    rtp_error err;
    /* x' = 2x + 1, y' = z, z' = -y (a rotation about x and a stretch) */
    static const double m[12] = {2, 0, 0, 1, 0, 0, 1, 0, 0, -1, 0, 0};
    const char *text = "v 1 2 3\nv 0 0 0\nv 0 1 0\nvn 1 1 0\nf 1//1 2//1 3//1\n";
    CHECK(rtpi_scene_create(NULL, &s) == RTP_OK);
    if (!s)
        return;
    CHECK(rtpi_read_obj(s, text, strlen(text), "x.obj", m, 7, &err) == RTP_OK);
    CHECK(s->pos[0] == 3 && s->pos[1] == 3 && s->pos[2] == -2);
    /* normal (1,1,0): inverse transpose gives (1/2, 0, -1), normalised */
    CHECK(near(s->nrm[0], 0.5 / sqrt(1.25), 1e-6) && near(s->nrm[1], 0, 1e-6) &&
          near(s->nrm[2], -1 / sqrt(1.25), 1e-6));
    CHECK(s->tris[0].mat == 7); /* the default material given */
    CHECK(s->nmats == 0);
    rtp_scene_destroy(s);
    {
        /* a mirror (scale -1 1 1) turns the face's corners the other way
           round: they are swapped back, so the geometric normal still
           points where the mirrored vertex normal does (+z here; it
           pointed to -z, the face lit from behind) */
        static const double mx[12] = {-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
        const char *q = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n";
        s = NULL;
        CHECK(rtpi_scene_create(NULL, &s) == RTP_OK);
        if (s && rtpi_read_obj(s, q, strlen(q), "q.obj", mx, 0, &err) == RTP_OK) {
            rtpi_v3 n = tri_normal(s, &s->tris[0]);
            CHECK_MSG(n.z > 0.0 && s->nrm[2] > 0.0f, "mirrored face normal z %g", n.z);
        } else {
            CHECK(0);
        }
        rtp_scene_destroy(s);
    }
    {
        /* a strong but regular stretch is taken (it was "singular"); a
           transform taking vertices past 1e18 is an error at the vertex */
        static const double st[12] = {1e6, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1e-3, 0};
        static const double big[12] = {1e30, 0, 0, 0, 0, 1e30, 0, 0, 0, 0, 1, 0};
        const char *q = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nf 1 2 3\n";
        s = NULL;
        CHECK(rtpi_scene_create(NULL, &s) == RTP_OK);
        CHECK(s && rtpi_read_obj(s, q, strlen(q), "q.obj", st, 0, &err) == RTP_OK);
        rtp_scene_destroy(s);
        s = NULL;
        CHECK(rtpi_scene_create(NULL, &s) == RTP_OK);
        CHECK(s && rtpi_read_obj(s, q, strlen(q), "q.obj", big, 0, &err) == RTP_ERR_PARSE &&
              err.line == 1 && strstr(err.message, "out of range"));
        rtp_scene_destroy(s);
    }
}

static void test_mtl(void)
{
    const char *dir = check_tmp_folder();
    char path[512];
    rtp_scene *s = NULL;
    rtp_error err;
    char buf[600];
    if (!dir[0])
        SKIP("cannot make a temporary folder");
    CHECK(check_write_file(dir, "t.ppm", "P3\n1 1\n255\n10 20 30\n") == 0);
    CHECK(check_write_file(dir, "a.mtl",
                     "# materials\nnewmtl red\n  Ka 1 0 0\n  Kd 0.8 0.4 0.2\n  Ks 0.3 0.6 0.9\n"
                     "  Ns 50\n  Ni 1.4\n  d 0.25\n  illum 2\n  Ke 0 0 0\n"
                     "newmtl glass\nKd 0 0 0\nTr 0.9\nmap_Kd -s 1 1 1 t.ppm\n"
                     "bump -bm 0.3 t.ppm\nmap_Ks t.ppm\n"
                     "newmtl grey\nKd 0.5\n") == 0);
    CHECK(check_write_file(dir, "a.obj",
                     "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                     "f 1 2 3\nusemtl red\nf 1 2 3\nusemtl glass\nf 1 2 3\n"
                     "usemtl grey\nf 1 2 3\n") == 0);
    snprintf(path, sizeof path, "%s/a.obj", dir);
    CHECK_MSG(rtp_scene_load(path, NULL, &s, &err) == RTP_OK, "%s",
              rtp_error_format(&err, buf, sizeof buf));
    if (s) {
        const rtpi_material *r = &s->mats[0], *g = &s->mats[1];
        CHECK(s->nmats == 4); /* red, glass, grey, then the default */
        CHECK(strcmp(r->name, "red") == 0 && strcmp(g->name, "glass") == 0);
        CHECK(near(r->kd, 0.8, 1e-6) && near(r->color[0], 1, 1e-6) &&
              near(r->color[1], 0.5, 1e-6) && near(r->color[2], 0.25, 1e-6));
        CHECK(near(r->ks, 0.6, 1e-6) && r->shine == 50 && near(r->ior, 1.4, 1e-6) &&
              near(r->kt, 0.75, 1e-6));
        CHECK(g->kd == 0 && g->color[0] == 1 && near(g->kt, 0.9, 1e-6));
        CHECK(g->tex == RTPI_TEX_IMAGE && g->bump == RTPI_BUMP_IMAGE &&
              near(g->bump_strength, 0.3, 1e-6) && g->tex_image == g->bump_image);
        CHECK(near(s->mats[2].kd, 0.5, 1e-6) && s->mats[2].color[2] == 1);
        CHECK(s->tris[0].mat == 3 && s->tris[1].mat == 0 && s->tris[2].mat == 1 &&
              s->tris[3].mat == 2);
        CHECK(rtp_scene_set(s, "mat.red.kd", "0.4", &err) == RTP_OK);
    }
    rtp_scene_destroy(s);
    s = NULL;

    /* map keywords in any letter case (Blender writes map_Bump), and file
       names with spaces, unquoted as exporters write them: the longest
       run of the last words that names a file (with "my t.ppm" and
       "t.ppm" both there, the last word alone took the wrong one) */
    CHECK(check_write_file(dir, "my t.ppm", "P3\n1 1\n255\n200 10 10\n") == 0);
    CHECK(check_write_file(dir, "c.mtl",
                     "newmtl sp\nmap_kd my t.ppm\nmap_Bump -bm 2 my t.ppm\n"
                     "newmtl plain\nMAP_KD t.ppm\n") == 0);
    CHECK(check_write_file(dir, "c.obj", "mtllib c.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                   "usemtl sp\nf 1 2 3\nusemtl plain\nf 1 2 3\n") == 0);
    snprintf(path, sizeof path, "%s/c.obj", dir);
    CHECK_MSG(rtp_scene_load(path, NULL, &s, &err) == RTP_OK, "%s",
              rtp_error_format(&err, buf, sizeof buf));
    if (s) {
        const rtpi_material *a = &s->mats[0], *b = &s->mats[1];
        CHECK(a->tex == RTPI_TEX_IMAGE && a->bump == RTPI_BUMP_IMAGE &&
              near(a->bump_strength, 2, 1e-6) && b->tex == RTPI_TEX_IMAGE);
        CHECK(a->tex_image != b->tex_image && s->ntexs == 2 &&
              strstr(s->texs[a->tex_image].path, "my t.ppm") != NULL);
    }
    rtp_scene_destroy(s);
    s = NULL;
    check_remove_file(dir, "my t.ppm");
    check_remove_file(dir, "c.mtl");
    check_remove_file(dir, "c.obj");

    /* errors inside the MTL carry the MTL's name and position */
    CHECK(check_write_file(dir, "b.mtl", "newmtl x\nKd 1 1\nnewmtl y\n") == 0);
    CHECK(check_write_file(dir, "b.obj", "mtllib b.mtl\n") == 0);
    snprintf(path, sizeof path, "%s/b.obj", dir);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE);
    CHECK(strstr(err.file, "b.mtl") && err.line == 2 && err.column == 7 &&
          strstr(err.message, "blue"));
    {
        /* a name's limit is 255 bytes (a tree file's), said as bytes: 127
           two-byte characters load, 128 are refused without "255
           characters" (they are 128) */
        char mtl[400];
        int i, n = sprintf(mtl, "newmtl ");
        for (i = 0; i < 127; i++)
            n += sprintf(mtl + n, "\xc3\xa9");
        sprintf(mtl + n, "\nKd 1 0 0\n");
        CHECK(check_write_file(dir, "b.mtl", mtl) == 0);
        CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_OK);
        rtp_scene_destroy(s);
        s = NULL;
        sprintf(mtl + n, "\xc3\xa9\nKd 1 0 0\n");
        CHECK(check_write_file(dir, "b.mtl", mtl) == 0);
        CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE);
        CHECK_MSG(err.line == 1 && strstr(err.message, "256 bytes: at most 255") &&
                      !strstr(err.message, "characters"),
                  "%s", err.message);
    }
    /* a bad number where an optional one may be is named by its field,
       not "unexpected 'nan' at the end of Kd" */
    {
        static const char *const bad[][2] = {{"newmtl x\nKd 0.5 nan 0.5\n", "Kd green, got 'nan'"},
                                             {"newmtl x\nKs 0.5 INF 0\n", "Ks green, got 'INF'"},
                                             {"newmtl x\nKd 0.5 0x1 0\n", "Kd green, got '0x1'"},
                                             {"newmtl x\nKd 0.5 1e999 0\n",
                                              "Kd green 1e999 is out of range"},
                                             {"newmtl x\nNs inf\n", "Ns value, got 'inf'"},
                                             /* (the name began there: "cannot load
                                                image 'nan 1 t.ppm'") */
                                             {"newmtl x\nmap_Kd -s 1 nan 1 t.ppm\n",
                                              "map_Kd: expected number for -s, got 'nan'"},
                                             {"newmtl x\nbump -o 1e999 t.ppm\n",
                                              "bump: -o 1e999 is out of range"}};
        size_t i;
        for (i = 0; i < sizeof bad / sizeof *bad; i++) {
            CHECK(check_write_file(dir, "b.mtl", bad[i][0]) == 0);
            CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE && s == NULL);
            CHECK_MSG(strstr(err.file, "b.mtl") && err.line == 2 &&
                          err.column == (i == 4 ? 4 : i == 5 ? 13 : i == 6 ? 9 : 8) &&
                          strstr(err.message, bad[i][1]),
                      "case %zu: %d:%d %s", i, err.line, err.column, err.message);
        }
    }
    /* MTL's "d -halo F" (a dissolve that follows the surface's angle to
       the eye) is a form rtp does not do: said so at -halo, not
       "expected number for d value, got '-halo'" as if the file were
       wrong */
    CHECK(check_write_file(dir, "b.mtl", "newmtl x\nd -halo 0.5\n") == 0);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE && s == NULL);
    CHECK_MSG(strstr(err.file, "b.mtl") && err.line == 2 && err.column == 3 &&
                  strstr(err.message, "d -halo") && strstr(err.message, "not supported") &&
                  !strstr(err.message, "expected number"),
              "%d:%d %s", err.line, err.column, err.message);
    CHECK(check_write_file(dir, "b.mtl", "Kd 1 1 1\n") == 0);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE);
    CHECK(err.line == 1 && err.column == 1 && strstr(err.message, "before any newmtl"));
    CHECK(check_write_file(dir, "b.mtl", "newmtl x\nKd 1 1 1\nfoo 1\n") == 0);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE);
    CHECK(err.line == 3 && strstr(err.message, "unknown MTL keyword 'foo'"));
    /* the numbers of statements rtp does not use are checked as Kd's
       ("Ka nan 0 0" loaded silently while "Kd nan" was refused), their
       other forms still read */
    {
        static const struct {
            const char *text;
            int col;
            const char *msg;
        } ign[] = {{"newmtl x\nKa nan 0 0\n", 4, "expected number for Ka value, got 'nan'"},
                   {"newmtl x\nKa x y z\n", 4, "expected number for Ka value, got 'x'"},
                   {"newmtl x\nKe 0 0 1e39\n", 8, "Ke value 3 1e39 is out of range"},
                   {"newmtl x\nTf 1 1 1 1\n", 10, "unexpected '1' at the end of Tf"},
                   {"newmtl x\nillum\n", 6, "unexpected end of line in illum"},
                   {"newmtl x\nPr inf\n", 4, "expected number for Pr value, got 'inf'"},
                   {"Ka 1 0 nan\n", 8, "expected number for Ka value 3, got 'nan'"}};
        size_t i;
        for (i = 0; i < sizeof ign / sizeof *ign; i++) {
            int line = strncmp(ign[i].text, "newmtl", 6) == 0 ? 2 : 1;
            CHECK(check_write_file(dir, "b.mtl", ign[i].text) == 0);
            CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE && s == NULL);
            CHECK_MSG(strstr(err.file, "b.mtl") && err.line == line &&
                          (ign[i].col == 1 || err.column == ign[i].col) &&
                          strstr(err.message, ign[i].msg),
                      "ignored case %zu: %d:%d %s", i, err.line, err.column, err.message);
        }
        CHECK(check_write_file(dir, "b.mtl",
                               "newmtl x\nKa 0.2\nKa xyz 1 1 1\nKe spectral e.rfl 2\n"
                               "Tf 1 1 1 # clear\nillum 2\nsharpness 60\nPr 0.5\nPs 1 1 1\n"
                               "disp -mm 0 1 d.png\nKd 0.5\n") == 0);
        CHECK_MSG(rtp_scene_load(path, NULL, &s, &err) == RTP_OK, "%s",
                  rtp_error_format(&err, buf, sizeof buf));
        rtp_scene_destroy(s);
        s = NULL;
        /* MTL values take their mat.N keys' range, float's (1e19 was
           refused: the key's material could not be written in a file) */
        CHECK(check_write_file(dir, "b.mtl", "newmtl x\nKd 3.4e38 0 0\nNs 3.4e38\nKa 3.4e38\n") ==
              0);
        CHECK_MSG(rtp_scene_load(path, NULL, &s, &err) == RTP_OK, "%s",
                  rtp_error_format(&err, buf, sizeof buf));
        CHECK(s && s->mats[0].kd == 3.4e38f && s->mats[0].shine == 3.4e38f);
        rtp_scene_destroy(s);
        s = NULL;
        CHECK(check_write_file(dir, "b.mtl", "newmtl x\nNs 3.5e38\n") == 0);
        CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE && s == NULL);
        CHECK_MSG(err.line == 2 && err.column == 4 && strstr(err.message, "Ns value 3.5e38 is out of range"),
                  "%d:%d %s", err.line, err.column, err.message);
    }
    CHECK(check_write_file(dir, "b.mtl", "newmtl x\nmap_Kd missing.png\n") == 0);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_IO);
    CHECK(err.line == 2 && err.column == 8 && strstr(err.message, "missing.png"));
    /* an image that is there but cannot be read: its line and column too
       (they were left unset: garbage) */
    CHECK(check_write_file(dir, "short.ppm", "P6\n4 4\n255\nabc") == 0);
    CHECK(check_write_file(dir, "b.mtl", "newmtl x\nmap_Kd -s 1 1 1 short.ppm\n") == 0);
    memset(&err, 0x55, sizeof err);
    CHECK(rtp_scene_load(path, NULL, &s, &err) != RTP_OK);
    CHECK_MSG(err.line == 2 && err.column == 17 && strstr(err.message, "short.ppm"),
              "%d:%d %s", err.line, err.column, err.message);
    check_remove_file(dir, "short.ppm");
    /* an option where the file name should be (it looked for an image
       named "-bm") */
    CHECK(check_write_file(dir, "b.mtl", "newmtl x\nbump -bm\n") == 0);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE);
    CHECK(err.line == 2 && strstr(err.message, "expected a number after -bm"));
    CHECK(check_write_file(dir, "b.mtl", "newmtl x\nmap_Kd -clamp\n") == 0);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE);
    CHECK(err.line == 2 && strstr(err.message, "expected a file name after the options"));
    /* an option's argument where the file name should be: "bump -bm 2"
       said "expected a number after -bm", "map_Kd -clamp on" looked for
       an image named "on"; with the file there, "-mm 0 t.ppm" (one
       argument short) still finds it */
    CHECK(check_write_file(dir, "b.mtl", "newmtl x\nbump -bm 2\n") == 0);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE);
    CHECK_MSG(err.line == 2 && err.column == 10 &&
                  strstr(err.message, "bump: expected a file name after the options"),
              "%d:%d %s", err.line, err.column, err.message);
    CHECK(check_write_file(dir, "b.mtl", "newmtl x\nmap_Kd -clamp on\n") == 0);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE);
    CHECK_MSG(err.line == 2 && err.column == 15 &&
                  strstr(err.message, "map_Kd: expected a file name after the options"),
              "%d:%d %s", err.line, err.column, err.message);
    CHECK(check_write_file(dir, "b.mtl", "newmtl x\nmap_Kd -mm 0 t.ppm\n") == 0);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_OK);
    rtp_scene_destroy(s);
    s = NULL;
    /* map options, read and not applied, have their arguments checked
       where a word follows them (they were read past: "-clamp yes"
       loaded) */
    {
        static const struct {
            const char *text;
            int col;
            const char *msg;
        } opts[] = {{"newmtl x\nmap_Kd -clamp yes t.ppm\n", 15, "map_Kd: -clamp takes on or off, got 'yes'"},
                    {"newmtl x\nbump -imfchan q t.ppm\n", 15, "bump: -imfchan takes r, g, b, m, l or z, got 'q'"},
                    {"newmtl x\nmap_Kd -boost x t.ppm\n", 15, "-boost takes a number, got 'x'"},
                    {"newmtl x\nmap_Kd -mm 0 nan t.ppm\n", 14, "-mm takes a number, got 'nan'"},
                    {"newmtl x\nmap_Kd -texres 1e999 t.ppm\n", 16, "-texres 1e999 is out of range"},
                    {"newmtl x\nmap_Kd -type cube t.ppm\n", 14, "-type takes sphere, cube_top"}};
        size_t i;
        for (i = 0; i < sizeof opts / sizeof *opts; i++) {
            CHECK(check_write_file(dir, "b.mtl", opts[i].text) == 0);
            CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE && s == NULL);
            CHECK_MSG(err.line == 2 && err.column == opts[i].col &&
                          strstr(err.message, opts[i].msg),
                      "option case %zu: %d:%d %s", i, err.line, err.column, err.message);
        }
        CHECK(check_write_file(dir, "b.mtl",
                               "newmtl x\nmap_Kd -clamp on -blendu off -blendv on -cc off "
                               "-boost 2 -mm 0 1 -texres 512 -imfchan l -type sphere -o 0 0 "
                               "-s 2 2 1 -t 0 0 t.ppm\nbump -imfchan z -bm 0.5 t.ppm\n") == 0);
        CHECK_MSG(rtp_scene_load(path, NULL, &s, &err) == RTP_OK, "%s",
                  rtp_error_format(&err, buf, sizeof buf));
        rtp_scene_destroy(s);
        s = NULL;
    }
    /* a missing mtllib is named */
    CHECK(check_write_file(dir, "b.obj", "v 0 0 0\nmtllib nothere.mtl\n") == 0);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_IO);
    CHECK(err.line == 2 && err.column == 8 && strstr(err.message, "nothere.mtl"));
    rtp_scene_destroy(s);

    check_remove_file(dir, "t.ppm");
    check_remove_file(dir, "a.mtl");
    check_remove_file(dir, "a.obj");
    check_remove_file(dir, "b.mtl");
    check_remove_file(dir, "b.obj");
}

/* Real exports: two Blender files' MTLs both define "Material" (each
   OBJ's faces take their own MTL's: the first file's red had taken both);
   the same OBJ included twice makes no copies; an NFF `name` still
   overrides both; "mtllib my model.mtl" (the OBJ's own name, unquoted)
   is one file; "map_Kd my missing tex.png" beside a tex.png is an error
   naming the whole name (it took tex.png silently). */
static void test_mtl_exports(void)
{
    const char *dir = check_tmp_folder();
    char path[512], buf[600];
    rtp_scene *s = NULL;
    rtp_error err;
    if (!dir[0])
        SKIP("cannot make a temporary folder");
    CHECK(check_write_file(dir, "ea.mtl", "newmtl Material\nKd 0.8 0 0\n") == 0);
    CHECK(check_write_file(dir, "eb.mtl", "newmtl Material\nKd 0 0 0.8\n") == 0);
    CHECK(check_write_file(dir, "ea.obj", "mtllib ea.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                    "usemtl Material\nf 1 2 3\n") == 0);
    CHECK(check_write_file(dir, "eb.obj", "mtllib eb.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                    "usemtl Material\nf 1 2 3\n") == 0);
    CHECK(check_write_file(dir, "two.nff", "include ea.obj\ninclude eb.obj\n"
                                     "include ea.obj translate 0 0 1\n") == 0);
    snprintf(path, sizeof path, "%s/two.nff", dir);
    CHECK_MSG(rtp_scene_load(path, NULL, &s, &err) == RTP_OK, "%s",
              rtp_error_format(&err, buf, sizeof buf));
    if (s) {
        CHECK(s->nmats == 2 && s->ntris == 3);
        CHECK(s->mats[s->tris[0].mat].color[0] == 1 && s->mats[s->tris[1].mat].color[2] == 1 &&
              s->tris[0].mat != s->tris[1].mat && s->tris[2].mat == s->tris[0].mat);
    }
    rtp_scene_destroy(s);
    s = NULL;
    /* one MTL reached by two spellings of its path is one file (string
       comparison made a copy of its materials per spelling) */
    CHECK(check_write_file(dir, "sp.nff", "include ea.obj\ninclude ./ea.obj\n") == 0);
    snprintf(path, sizeof path, "%s/sp.nff", dir);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_OK);
    CHECK(s && s->nmats == 1 && s->tris[0].mat == 0 && s->tris[1].mat == 0);
    rtp_scene_destroy(s);
    s = NULL;
    check_remove_file(dir, "sp.nff");
    /* names with dots, as exporters make them ("Material.001"): a key's
       field is after its last dot (mat.Material.001.kd said "no such
       material") */
    CHECK(check_write_file(dir, "dot.mtl", "newmtl Material.001\nKd 0.8 0 0\n"
                                     "newmtl glass.red.kd\nKd 0 1 0\n") == 0);
    CHECK(check_write_file(dir, "dot.obj", "mtllib dot.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                     "usemtl Material.001\nf 1 2 3\nusemtl glass.red.kd\n"
                                     "f 1 3 2\n") == 0);
    snprintf(path, sizeof path, "%s/dot.obj", dir);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_OK);
    if (s) {
        CHECK_MSG(rtp_scene_set(s, "mat.Material.001.kd", "0.25", &err) == RTP_OK, "%s",
                  rtp_error_format(&err, buf, sizeof buf));
        CHECK(rtp_scene_set(s, "mat.glass.red.kd.color", "0.5,0.25,0", &err) == RTP_OK);
        CHECK(rtp_scene_get(s, "mat.Material.001.kd", buf, sizeof buf, &err) == RTP_OK &&
              strcmp(buf, "0.25") == 0);
        CHECK(s->mats[s->tris[0].mat].kd == 0.25f && s->mats[s->tris[1].mat].color[1] == 0.25f &&
              s->mats[s->tris[1].mat].kd != 0.25f);
        CHECK(rtp_scene_set(s, "mat.Material.kd", "0.5", &err) == RTP_ERR_KEY);
        CHECK(rtp_scene_set(s, "mat.Material.001.", "0.5", &err) == RTP_ERR_KEY);
    }
    rtp_scene_destroy(s);
    s = NULL;
    check_remove_file(dir, "dot.obj");
    check_remove_file(dir, "dot.mtl");
    CHECK(check_write_file(dir, "ov.nff", "f 0 1 0 1 0 10 0 1\nname Material\ns 0 0 0 1\n"
                                    "include ea.obj\ninclude eb.obj\n") == 0);
    snprintf(path, sizeof path, "%s/ov.nff", dir);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_OK);
    CHECK(s && s->nmats == 1 && s->tris[0].mat == 0 && s->tris[1].mat == 0);
    rtp_scene_destroy(s);
    s = NULL;

    CHECK(check_write_file(dir, "my model.mtl", "newmtl X\nKd 0 1 0\n") == 0);
    CHECK(check_write_file(dir, "my model.obj", "mtllib my model.mtl\nv 0 0 0\nv 1 0 0\n"
                                          "v 0 1 0\nusemtl X\nf 1 2 3\n") == 0);
    snprintf(path, sizeof path, "%s/my model.obj", dir);
    CHECK_MSG(rtp_scene_load(path, NULL, &s, &err) == RTP_OK, "%s",
              rtp_error_format(&err, buf, sizeof buf));
    CHECK(s && s->nmats == 1 && s->mats[0].color[1] == 1);
    rtp_scene_destroy(s);
    s = NULL;
    /* several names still are several files */
    CHECK(check_write_file(dir, "m2.obj", "mtllib ea.mtl my\nv 0 0 0\n") == 0);
    snprintf(path, sizeof path, "%s/m2.obj", dir);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_IO);
    CHECK(err.line == 1 && err.column == 15 && strstr(err.message, "'my'"));

    CHECK(check_write_file(dir, "tex.ppm", "P3\n1 1\n255\n10 20 30\n") == 0);
    CHECK(check_write_file(dir, "mt.mtl", "newmtl a\nmap_Kd -s 1 1 -blendu on my missing tex.ppm\n") == 0);
    CHECK(check_write_file(dir, "mt.obj", "mtllib mt.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                    "usemtl a\nf 1 2 3\n") == 0);
    snprintf(path, sizeof path, "%s/mt.obj", dir);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_IO);
    CHECK_MSG(err.line == 2 && err.column == 26 && strstr(err.message, "'my missing tex.ppm'"),
              "%s", rtp_error_format(&err, buf, sizeof buf));
    /* after an option this reader cannot count, the last words that name
       a file */
    CHECK(check_write_file(dir, "mt.mtl", "newmtl a\nmap_Kd -zz 3 tex.ppm\n") == 0);
    CHECK_MSG(rtp_scene_load(path, NULL, &s, &err) == RTP_OK, "%s",
              rtp_error_format(&err, buf, sizeof buf));
    CHECK(s && s->mats[0].tex == RTPI_TEX_IMAGE);
    rtp_scene_destroy(s);
    s = NULL;

    /* Windows exporters' names: "maps\tex.ppm", "mats\w.mtl" name files
       in sub-folders; "C:\Users\me\tex.ppm" the file beside the MTL (the
       scene was refused: no such file) */
    snprintf(path, sizeof path, "%s/maps", dir);
    CHECK(mkdir(path, 0700) == 0);
    snprintf(path, sizeof path, "%s/mats", dir);
    CHECK(mkdir(path, 0700) == 0);
    CHECK(check_write_file(dir, "maps/t2.ppm", "P3\n1 1\n255\n40 50 60\n") == 0);
    CHECK(check_write_file(dir, "mats/w.mtl",
                     "newmtl a\nmap_Kd ..\\maps\\t2.ppm\nnewmtl b\n"
                     "map_Kd C:\\Users\\me\\Documents\\tex.ppm\n") == 0);
    CHECK(check_write_file(dir, "mats/tex.ppm", "P3\n1 1\n255\n10 20 30\n") == 0);
    CHECK(check_write_file(dir, "w.obj", "mtllib mats\\w.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                   "usemtl a\nf 1 2 3\nusemtl b\nf 1 3 2\n") == 0);
    snprintf(path, sizeof path, "%s/w.obj", dir);
    CHECK_MSG(rtp_scene_load(path, NULL, &s, &err) == RTP_OK, "%s",
              rtp_error_format(&err, buf, sizeof buf));
    if (s) {
        CHECK(s->ntexs == 2 && s->mats[s->tris[0].mat].tex == RTPI_TEX_IMAGE &&
              s->mats[s->tris[1].mat].tex == RTPI_TEX_IMAGE &&
              s->mats[s->tris[0].mat].tex_image != s->mats[s->tris[1].mat].tex_image);
    }
    rtp_scene_destroy(s);
    s = NULL;
    /* a name that names nothing either way is still an error naming it */
    CHECK(check_write_file(dir, "mats/w.mtl", "newmtl a\nmap_Kd maps\\none.ppm\n") == 0);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_IO && !s &&
          strstr(err.message, "'maps\\none.ppm'"));
    check_remove_file(dir, "mats/w.mtl");
    check_remove_file(dir, "mats/tex.ppm");
    check_remove_file(dir, "maps/t2.ppm");
    check_remove_file(dir, "w.obj");
    check_remove_file(dir, "mats");
    check_remove_file(dir, "maps");

    /* a missing "mtllib my model.mtl" is named whole (it was 'my') */
    CHECK(check_write_file(dir, "m3.obj", "mtllib no model.mtl\nv 0 0 0\n") == 0);
    snprintf(path, sizeof path, "%s/m3.obj", dir);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_IO);
    CHECK_MSG(err.line == 1 && err.column == 8 && strstr(err.message, "'no model.mtl'"), "%s",
              rtp_error_format(&err, buf, sizeof buf));
    check_remove_file(dir, "m3.obj");

    /* a bump strength past the float range (-bm 1e40: stored as inf, the
       tree file written from it unreadable) is refused as NFF's is */
    CHECK(check_write_file(dir, "bm.mtl", "newmtl a\nbump -bm 1e40 tex.ppm\n") == 0);
    CHECK(check_write_file(dir, "bm.obj", "mtllib bm.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                    "usemtl a\nf 1 2 3\n") == 0);
    snprintf(path, sizeof path, "%s/bm.obj", dir);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE && !s);
    CHECK_MSG(err.line == 2 && err.column == 10 && strstr(err.message, "out of range"), "%s",
              rtp_error_format(&err, buf, sizeof buf));
    check_remove_file(dir, "bm.mtl");
    check_remove_file(dir, "bm.obj");

    /* "newmtl Material #25", "newmtl Material #26": the comment cut both
       to "Material", and the second was dropped without a word */
    CHECK(check_write_file(dir, "hh.mtl", "newmtl Material #25\nKd 1 0 0\nnewmtl Material #26\n"
                                    "Kd 0 0 1\n") == 0);
    CHECK(check_write_file(dir, "hh.obj", "mtllib hh.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                    "usemtl Material #25\nf 1 2 3\n") == 0);
    snprintf(path, sizeof path, "%s/hh.obj", dir);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_ERR_PARSE && !s);
    CHECK_MSG(err.line == 3 && strstr(err.message, "'#' after a blank"), "%s",
              rtp_error_format(&err, buf, sizeof buf));
    check_remove_file(dir, "hh.mtl");
    check_remove_file(dir, "hh.obj");

    check_remove_file(dir, "ea.mtl");
    check_remove_file(dir, "eb.mtl");
    check_remove_file(dir, "ea.obj");
    check_remove_file(dir, "eb.obj");
    check_remove_file(dir, "two.nff");
    check_remove_file(dir, "ov.nff");
    check_remove_file(dir, "my model.mtl");
    check_remove_file(dir, "my model.obj");
    check_remove_file(dir, "m2.obj");
    check_remove_file(dir, "tex.ppm");
    check_remove_file(dir, "mt.mtl");
    check_remove_file(dir, "mt.obj");
}

/* Thousands of names (the index that replaced a scan of every material
   at each newmtl and usemtl grows and rehashes many times): each face
   takes the material its usemtl names, duplicates across files stay
   apart, and the NFF reader still refuses a name used twice. */
/* '#' inside a word is part of it: 3ds Max's "Material#25" names stay
   two materials (the word ended at '#' and the rest of the line was a
   comment: one material "Mat", the second face red); a comment still
   starts a word.  A backslash ending a line continues the statement
   (the OBJ specification's continuation), LF or CRLF, in statements read
   past too; a face's error on the continued line names that line. */
static void test_hash_and_continuation(void)
{
    const char *dir = check_tmp_folder();
    char path[512], buf[600];
    rtp_scene *s = NULL;
    rtp_error err;
    if (!dir[0])
        SKIP("cannot make a temporary folder");
    /* (a comment's last backslash continues nothing, on a line read past
       too: "illum 2 # note\" ate the Kd after it; a lone backslash joins
       the next line) */
    CHECK(check_write_file(dir, "h.mtl",
                     "newmtl Mat#1 # red\nillum 2 # note \\\nKd 1 0 0\nnewmtl Mat#2\nKd 0 1 0\n") ==
          0);
    CHECK(check_write_file(dir, "h.obj",
                     "mtllib h.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                     "usemtl Mat#1\nf 1 2 3 #first\nusemtl Mat#2\nf 1 \\\n 3 \\\r\n 4\n"
                     "vp 0.5 \\\n 0.5\ng one # c \\\n\\\nf 2 3 4\n") == 0);
    snprintf(path, sizeof path, "%s/h.obj", dir);
    CHECK_MSG(rtp_scene_load(path, NULL, &s, &err) == RTP_OK, "%s",
              rtp_error_format(&err, buf, sizeof buf));
    if (s) {
        CHECK_MSG(s->nmats == 2 && s->ntris == 3 && s->tris[0].mat != s->tris[1].mat &&
                      s->tris[2].mat == s->tris[1].mat,
                  "%zu materials, %zu triangles", s->nmats, s->ntris);
        CHECK(s->nmats == 2 && strcmp(s->mats[s->tris[0].mat].name, "Mat#1") == 0 &&
              s->mats[s->tris[0].mat].color[0] == 1 &&
              strcmp(s->mats[s->tris[1].mat].name, "Mat#2") == 0 &&
              s->mats[s->tris[1].mat].color[1] == 1);
        /* the continued face: corners 1, 3, 4 */
        CHECK(s->ntris == 3 && s->pos[3 * s->tris[1].v[1] + 1] == 1.0 &&
              s->pos[3 * s->tris[1].v[2] + 0] == 0.0);
    }
    rtp_scene_destroy(s);
    check_remove_file(dir, "h.mtl");
    check_remove_file(dir, "h.obj");
}

static void test_many_names(void)
{
    const char *dir = check_tmp_folder();
    char path[512], line[128];
    size_t i, len = 0, cap = 1 << 20;
    char *mtl = (char *)malloc(cap), *objt = (char *)malloc(4 * cap);
    rtp_scene *s = NULL;
    rtp_error err;
    const int n = 3000;
    if (!dir[0] || !mtl || !objt) {
        free(mtl);
        free(objt);
        SKIP("cannot make a temporary folder");
    }
    for (i = 0; i < (size_t)n; i++)
        len += (size_t)snprintf(mtl + len, cap - len, "newmtl m%zu\nKd %g 0.5 0.5\n", i,
                                (double)i / n);
    CHECK(check_write_file(dir, "many.mtl", mtl) == 0);
    len = (size_t)snprintf(objt, 4 * cap, "mtllib many.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n");
    for (i = 0; i < (size_t)n; i++) /* in another order: 7 is prime to 3000 */
        len += (size_t)snprintf(objt + len, 4 * cap - len, "usemtl m%zu\nf 1 2 3\n",
                                (i * 7) % (size_t)n);
    CHECK(check_write_file(dir, "many.obj", objt) == 0);
    snprintf(path, sizeof path, "%s/many.obj", dir);
    CHECK(rtp_scene_load(path, NULL, &s, &err) == RTP_OK);
    if (s) {
        int ok = s->nmats == (size_t)n && s->ntris == (size_t)n;
        for (i = 0; ok && i < (size_t)n; i++) {
            snprintf(line, sizeof line, "m%zu", (i * 7) % (size_t)n);
            ok = strcmp(s->mats[s->tris[i].mat].name, line) == 0;
        }
        CHECK(ok);
    }
    rtp_scene_destroy(s);
    s = NULL;
    /* NFF: every material named; the last name repeats the first */
    len = 0;
    for (i = 0; i < (size_t)n; i++)
        len += (size_t)snprintf(objt + len, 4 * cap - len, "f 1 1 1 1 0 1 0 1\nname n%zu\n", i);
    CHECK(rtp_scene_load_memory(objt, len, "names.nff", "nff", NULL, &s, &err) == RTP_OK);
    CHECK(s && s->nmats == (size_t)n);
    rtp_scene_destroy(s);
    s = NULL;
    len += (size_t)snprintf(objt + len, 4 * cap - len, "f 1 1 1 1 0 1 0 1\nname n0\n");
    CHECK(rtp_scene_load_memory(objt, len, "names.nff", "nff", NULL, &s, &err) == RTP_ERR_PARSE);
    CHECK(strstr(err.message, "already used by material 0") != NULL);
    check_remove_file(dir, "many.mtl");
    check_remove_file(dir, "many.obj");
    free(mtl);
    free(objt);
}

typedef struct bad_case {
    const char *text;
    int line, col;
    const char *msg;
} bad_case;

#define TRI "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
static const bad_case bad_obj[] = {
    {"v 1 2\n", 1, 6, "unexpected end of line in v (vertex), expected z"},
    {"v 1 2", 1, 6, "unexpected end of file in v (vertex), expected z"},
    {"v 1 2 inf\n", 1, 7, "expected number for v (vertex) z, got 'inf'"},
    {"v 1 2 nan\n", 1, 7, "got 'nan'"},
    {"v 1 2 3 4 5 6 7 8\n", 1, 17, "unexpected '8'"},
    {"v 1 2 3 w\n", 1, 9, "unexpected 'w'"},
    /* a bad number where an optional one may be: named as one, not
       "unexpected 'nan' at the end of v (vertex)" */
    {"v 1 2 3 nan\n", 1, 9, "expected number for v (vertex) value 4, got 'nan'"},
    {"v 1 2 3 1 -inf 1\n", 1, 11, "expected number for v (vertex) value 5, got '-inf'"},
    {"vt 0.5 Infinity\n", 1, 8, "expected number for vt (texture vertex) v, got 'Infinity'"},
    {"vt 0.5 0.5 nan(1)\n", 1, 12, "expected number for vt (texture vertex) value 3, got 'nan(1)'"},
    {"vn 1 2 3 4\n", 1, 10, "unexpected '4'"},
    {"vt\n", 1, 3, "expected u"},
    {"v 0 0 0\nf 1 2 3\n", 2, 5, "vertex index 2 out of range (1 vertex so far)"},
    {TRI "f 1 2 -4\n", 4, 7, "vertex index -4 out of range (3 vertices so far)"},
    {TRI "f 0 1 2\n", 4, 3, "vertex index 0 is invalid"},
    {TRI "f 1 2\n", 4, 1, "face has 2 vertices, needs at least 3"},
    {TRI "f\n", 4, 1, "face has 0 vertices"},
    {TRI "f 1/1 2/1 3/1\n", 4, 5, "texture vertex index 1 out of range (0 texture vertices so far)"},
    {TRI "f 1//1 2 3\n", 4, 6, "normal index 1 out of range (0 normals so far)"},
    {TRI "f 1/x 2 3\n", 4, 5, "expected texture vertex index in face, got 'x'"},
    {TRI "f 1/ 2 3\n", 4, 3, "malformed face vertex '1/'"},
    {TRI "f 1.5 2 3\n", 4, 3, "expected vertex index in face, got '1.5'"},
    {TRI "f 1 2 99999999999\n", 4, 7, "expected vertex index"},
    {"usemtl foo\n", 1, 8, "unknown material 'foo'"},
    {"usemtl\n", 1, 7, "expected a name"},
    {"bogus 1\n", 1, 1, "unknown OBJ keyword 'bogus'"},
    /* vp, not used, has its numbers checked as v's */
    {"vp 0.5 nan\n", 1, 8, "expected number for vp value 2, got 'nan'"},
    {"vp\n", 1, 3, "expected value"},
    {"v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 x\r\n", 4, 7, "got 'x'"},
    /* MSVC's NaN and infinity are words, not -1 and a comment (it read
       the vertex as z = -1, the normal as z = 1) */
    {"v 1 1 -1.#IND00\n", 1, 7, "expected number for v (vertex) z, got '-1.#IND00'"},
    {"vn 0 0 1.#QNAN0\n", 1, 8, "expected number for vn (normal) z, got '1.#QNAN0'"},
    {"v 1 2 1e400\n", 1, 7, "v (vertex) z 1e400 is out of range"},
    /* a continued line goes on to the next; its errors name that line */
    {TRI "f 1 2 \\\n  x\n", 5, 3, "got 'x'"},
    /* l and p, not drawn, have their indices checked as a face's (they
       were read past: "l 1 99" loaded) */
    {TRI "l 1 4\n", 4, 5, "vertex index 4 out of range (3 vertices so far)"},
    {TRI "p 0\n", 4, 3, "vertex index 0 is invalid"},
    {TRI "p 1 -4\n", 4, 5, "vertex index -4 out of range"},
    {TRI "l 1\n", 4, 1, "line has 1 vertex, needs at least 2"},
    {TRI "p\n", 4, 1, "point has 0 vertices, needs at least 1"},
    {TRI "l 1/1 2/1\n", 4, 5, "texture vertex index 1 out of range (0 texture vertices so far)"},
    {TRI "l 1//1 2\n", 4, 3, "malformed line vertex '1//1' (v or v/vt)"},
    {TRI "l 1/ 2\n", 4, 3, "malformed line vertex '1/'"},
    {TRI "p 1/1\n", 4, 3, "malformed point vertex '1/1' (v alone)"},
    {TRI "l 1 x\n", 4, 5, "expected vertex index in line, got 'x'"},
    /* s: a group number or off (read past: "s x y" loaded) */
    {"s\n", 1, 1, "s: expected a smoothing group"},
    {"s -1\n", 1, 3, "s: expected a smoothing group (a number, 0 or more, or off), got '-1'"},
    {"s 1.5\n", 1, 3, "got '1.5'"},
    {"s 1 2\n", 1, 5, "unexpected '2' at the end of s"},
};

static void test_bad_inputs(void)
{
    size_t i;
    for (i = 0; i < sizeof bad_obj / sizeof *bad_obj; i++) {
        const bad_case *b = &bad_obj[i];
        rtp_scene *s = NULL;
        rtp_error err;
        rtp_status st;
        memset(&err, 0, sizeof err);
        st = load(b->text, "bad.obj", &s, &err);
        CHECK_MSG(st == RTP_ERR_PARSE && err.line == b->line && err.column == b->col &&
                      strstr(err.message, b->msg) != NULL && strcmp(err.file, "bad.obj") == 0,
                  "case %zu: got status %d at %d:%d '%s', expected %d:%d '%s'", i, (int)st,
                  err.line, err.column, err.message, b->line, b->col, b->msg);
        rtp_scene_destroy(s);
    }
}

static void test_truncation(void)
{
    static const char text[] =
        "# a mesh\no a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\n"
        "vn 0 0 1\ng g\ns 1\nf 1/1/1 2/2/1 3/3/1\nf -4//-1 -3//-1 -2//-1 -1//-1\n"
        "f 1/1 2/2 3/3\nf 4 3 2 1\n";
    size_t len, ok = 0, other = 0;
    for (len = 0; len <= sizeof text - 1; len++) {
        char *copy = (char *)malloc(len ? len : 1);
        rtp_scene *s = NULL;
        rtp_error err;
        rtp_status st;
        if (!copy)
            return;
        memcpy(copy, text, len);
        st = rtp_scene_load_memory(copy, len, "trunc.obj", "obj", NULL, &s, &err);
        if (st == RTP_OK)
            ok++;
        else if (!(st == RTP_ERR_PARSE && err.line >= 1 && err.column >= 1))
            other++;
        rtp_scene_destroy(s);
        free(copy);
    }
    CHECK(ok > 10);
    CHECK(other == 0);
}

static void test_shared_meshes(void)
{
    static const struct {
        const char *name;
        size_t tris;
    } meshes[] = {{"stanford-bunny.obj", 69451}, {"teapot.obj", 6320},
                  {"spot_triangulated.obj", 5856}, {"spot_quadrangulated.obj", 5856},
                  {"suzanne.obj", 968}, {"CornellBox-Original.obj", 36}};
    const char *dir = check_shared_scenes();
    size_t i;
    if (!dir)
        SKIP("../shared/scenes not found (set RTP_SHARED_SCENES)");
    for (i = 0; i < sizeof meshes / sizeof *meshes; i++) {
        char path[512], buf[600];
        rtp_scene *s = NULL;
        rtp_error err;
        snprintf(path, sizeof path, "%s/meshes/%s", dir, meshes[i].name);
        CHECK_MSG(rtp_scene_load(path, NULL, &s, &err) == RTP_OK, "%s",
                  rtp_error_format(&err, buf, sizeof buf));
        if (s)
            CHECK_MSG(s->ntris == meshes[i].tris, "%s: %zu triangles, expected %zu",
                      meshes[i].name, s->ntris, meshes[i].tris);
        if (s && i == sizeof meshes / sizeof *meshes - 1)
            CHECK(s->nmats >= 7 && rtp_scene_set(s, "mat.leftWall.color", "1,0,0", &err) ==
                                       RTP_OK);
        rtp_scene_destroy(s);
    }
}

/* A Bezier patch under a mirror (scale -1 1 1) keeps its side: its
   triangles' normals and vertex normals point as the unmirrored
   patch's do in z (both pointed the other way: a mirrored glass teapot
   was refracted as if seen from inside, 0.5 off its mirror image). */
static void test_bezier_mirrored(void)
{
    static const double id[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    static const double mx[12] = {-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    char bpt[1024];
    size_t o = 0;
    int k, pass;
    double z[2] = {0, 0};
    o += (size_t)snprintf(bpt + o, sizeof bpt - o, "1\n");
    for (k = 1; k <= 16; k++)
        o += (size_t)snprintf(bpt + o, sizeof bpt - o, "%d%s", k, k < 16 ? "," : "\n");
    o += (size_t)snprintf(bpt + o, sizeof bpt - o, "16\n");
    for (k = 0; k < 16; k++) /* a gently curved patch */
        o += (size_t)snprintf(bpt + o, sizeof bpt - o, "%g,%g,%g\n", (k / 4) / 3.0,
                              (k % 4) / 3.0, ((k / 4) % 3 ? 0.2 : 0.0));
    for (pass = 0; pass < 2; pass++) {
        rtp_scene *s = NULL;
        rtp_error err;
        size_t i, agree = 0;
        CHECK(rtpi_scene_create(NULL, &s) == RTP_OK);
        if (!s)
            return;
        CHECK(rtpi_read_bpt(s, bpt, o, "p.bpt", 4, pass ? mx : id, 0, &err) == RTP_OK);
        for (i = 0; i < s->ntris; i++) {
            rtpi_v3 g = tri_normal(s, &s->tris[i]);
            const float *vn = s->nrm + 3 * (size_t)s->tris[i].n[0];
            agree += g.x * vn[0] + g.y * vn[1] + g.z * vn[2] > 0.0;
            z[pass] += g.z;
        }
        CHECK_MSG(s->ntris > 0 && agree == s->ntris,
                  "%s: %lu of %lu triangles agree with their normals", pass ? "mirrored" : "plain",
                  (unsigned long)agree, (unsigned long)s->ntris);
        rtp_scene_destroy(s);
    }
    CHECK_MSG(z[0] * z[1] > 0.0, "mirrored patch faces z %g, plain %g", z[1], z[0]);
}

/* A patch file's point past the range is said to be out of range (it was
   "expected number for point 1 x, got '1e999'"), a word as no number. */
static void test_bezier_bad_number(void)
{
    static const char *const bad[][2] = {
        {"1e999", "point 1 x 1e999 is out of range (|x| <= 1e+18)"},
        {"1e19", "point 1 x 1e19 is out of range"},
        {"nan", "expected number for point 1 x, got 'nan'"}};
    size_t i;
    for (i = 0; i < sizeof bad / sizeof *bad; i++) {
        char bpt[1024];
        size_t o = 0;
        int k;
        rtp_scene *s = NULL;
        rtp_error err;
        o += (size_t)snprintf(bpt + o, sizeof bpt - o, "1\n");
        for (k = 1; k <= 16; k++)
            o += (size_t)snprintf(bpt + o, sizeof bpt - o, "%d%s", k, k < 16 ? "," : "\n");
        o += (size_t)snprintf(bpt + o, sizeof bpt - o, "16\n%s,0,0\n", bad[i][0]);
        for (k = 1; k < 16; k++)
            o += (size_t)snprintf(bpt + o, sizeof bpt - o, "%d,%d,0\n", k / 4, k % 4);
        CHECK(rtpi_scene_create(NULL, &s) == RTP_OK);
        if (!s)
            return;
        memset(&err, 0, sizeof err);
        CHECK(rtpi_read_bpt(s, bpt, o, "p.bpt", 2, NULL, 0, &err) == RTP_ERR_PARSE);
        CHECK_MSG(err.line == 4 && err.column == 1 && strstr(err.message, bad[i][1]),
                  "%s: %d:%d %s", bad[i][0], err.line, err.column, err.message);
        rtp_scene_destroy(s);
    }
}

int main(void)
{
    RUN(test_faces);
    RUN(test_ngon);
    RUN(test_cr_line_ends);
    RUN(test_tiny_normal);
    RUN(test_xform);
    RUN(test_mtl);
    RUN(test_mtl_exports);
    RUN(test_many_names);
    RUN(test_hash_and_continuation);
    RUN(test_bad_inputs);
    RUN(test_truncation);
    RUN(test_shared_meshes);
    if (check_tmpdir[0])
        rmdir(check_tmpdir);
    RUN(test_bezier_mirrored);
    RUN(test_bezier_bad_number);
    return check_report();
}
