/* The 3D Delaunay tessellation under vesselhex's medial axis (src/centerline_extract/qhull.rs),
 * computed by Qhull's reentrant library (vendor/qhull_r, unmodified) as the lower convex hull of
 * the points lifted to the paraboloid, the way the `qhull` crate 0.4.1 drove it before: the same
 * options, the same calls in the same order, the facets read in the same order, so that the
 * tetrahedra, and the centerlines made from them, are the same to the bit.
 *
 * Why C and not Rust: Qhull reports an error by longjmp to a setjmp of its caller, which Rust
 * code cannot be. The whole run, from the options to the read-out, happens here under one setjmp.
 *
 * Nothing is written to a file, stdout or stderr: Qhull's messages go to a stream in memory and
 * come back in the result when the run fails. One qhT per call: calls may run in parallel. */

#define _POSIX_C_SOURCE 200809L /* open_memstream */

#include <setjmp.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "libqhull_r.h"
#include "io_r.h" /* qh_prepare_output */

/* Must match `Tessellation` in src/centerline_extract/qhull.rs. */
typedef struct {
    int32_t *corners;    /* 4 per tetrahedron: indices of the input points */
    int32_t *neighbours; /* 4 per tetrahedron: the tetrahedron across each face, -1 where none */
    size_t count;        /* tetrahedra */
    char *message;       /* on failure: what went wrong, NUL-terminated (Qhull's own words) */
} vh_tessellation;

/* The dimension of the lifted points (x, y, z, |p|^2). */
#define LIFTED 4

/* A copy of `text` the caller frees, or NULL. */
static char *copy_text(const char *text) {
    size_t n = strlen(text) + 1;
    char *copy = malloc(n);
    if (copy) memcpy(copy, text, n);
    return copy;
}

/* The input point a vertex stands for, or -1 when its point is not one of them (as the qhull
 * crate's Vertex::index: by its address in qh->first_point, the joggled copy of the input). */
static int32_t point_index(qhT *qh, vertexT *vertex) {
    if (vertex->id == 0 || !vertex->point) return -1;
    ptrdiff_t offset = vertex->point - qh->first_point;
    if (offset < 0 || offset >= (ptrdiff_t)qh->num_points * qh->hull_dim) return -1;
    return (int32_t)(offset / qh->hull_dim);
}

/* The corners of a facet that is a lower Delaunay tetrahedron, or 0 when it is not one. */
static int tetrahedron_corners(qhT *qh, facetT *facet, int32_t corners[4]) {
    vertexT *vertex, **vertexp;
    int n = 0;
    if (facet->id == 0 || facet->upperdelaunay || !facet->vertices) return 0;
    FOREACHvertex_(facet->vertices) {
        int32_t index = point_index(qh, vertex);
        if (index < 0) continue;
        if (n == 4) return 0;
        corners[n++] = index;
    }
    return n == 4;
}

/* Reads the tetrahedra out of a finished hull: facets in facet_list order, corners in the order
 * of each facet's vertex set, neighbours in the order of its neighbour set. 0, or 1 with
 * out->message set. */
static int read_tetrahedra(qhT *qh, vh_tessellation *out) {
    facetT *facet, *neighbor, **neighborp;
    int32_t corners[4];
    size_t count = 0, ids = qh->facet_id;
    int32_t *tet_of_id = malloc((ids ? ids : 1) * sizeof(int32_t));
    if (!tet_of_id) {
        out->message = copy_text("out of memory for the Delaunay tetrahedra");
        return 1;
    }
    for (size_t i = 0; i < ids; i++) tet_of_id[i] = -1;
    for (facet = qh->facet_list; facet; facet = facet->next)
        if (tetrahedron_corners(qh, facet, corners)) tet_of_id[facet->id] = (int32_t)count++;
    out->corners = malloc((count ? count : 1) * 4 * sizeof(int32_t));
    out->neighbours = malloc((count ? count : 1) * 4 * sizeof(int32_t));
    if (!out->corners || !out->neighbours) {
        free(tet_of_id);
        out->message = copy_text("out of memory for the Delaunay tetrahedra");
        return 1;
    }
    for (facet = qh->facet_list; facet; facet = facet->next) {
        if (!tetrahedron_corners(qh, facet, corners)) continue;
        int32_t t = tet_of_id[facet->id], *slots = out->neighbours + 4 * (size_t)t;
        int n = 0;
        memcpy(out->corners + 4 * (size_t)t, corners, sizeof corners);
        if (facet->neighbors) {
            FOREACHneighbor_(facet) {
                if (n == 4) {
                    free(tet_of_id);
                    out->message = copy_text("Qhull gave a tetrahedron with more than four neighbours");
                    return 1;
                }
                slots[n++] = neighbor->id < ids ? tet_of_id[neighbor->id] : -1;
            }
        }
        while (n < 4) slots[n++] = -1;
    }
    out->count = count;
    free(tet_of_id);
    return 0;
}

/* The lifted points' lower hull by Qhull, read into `out`: 0, Qhull's exit code (it said why in
 * `messages`), or -1 with out->message set. `lifted`: `count` points of LIFTED coordinates. */
static int tessellate(qhT *qh, FILE *messages, double *lifted, int32_t count, vh_tessellation *out) {
    /* The qhull crate's options: qhull 'QJ' (joggled input), then the Delaunay lift and 'Qbb'
     * (the last coordinate scaled) set on the qhT, as its builder did. */
    static char program[] = "qhull", joggle[] = "QJ";
    static char hidden_options[] =
        " d v H Qbb Qf Qg Qm Qr Qu Qv Qx Qz TR E V Fp Gt Q0 Q1 Q2 Q3 Q4 Q5 Q6 Q7 Q8 Q9 Q10 Q11 Q15 ";
    char *argv[] = {program, joggle, NULL};
    qh_init_A(qh, NULL, messages, messages, 2, argv); /* outside the setjmp, as Qhull's programs */
    volatile int status = setjmp(qh->errexit);
    if (status == 0) {
        qh->NOerrexit = False;
        qh_checkflags(qh, qh->qhull_command, hidden_options);
        qh_initflags(qh, qh->qhull_command);
        qh->DELAUNAY = True;
        qh->SCALElast = True;
        qh_init_B(qh, lifted, count, LIFTED, False);
        qh_qhull(qh);
        qh_prepare_output(qh);
        status = read_tetrahedra(qh, out) ? -1 : 0;
    }
    qh->NOerrexit = True;
    return status;
}

/* The Delaunay tetrahedra of `count` points given lifted (x, y, z, w per point; the caller
 * centres, scales and lifts them). Returns 0 with `out` filled, or non-zero with out->message.
 * Either way the caller hands `out` to vh_tessellation_free. */
int vh_delaunay(double *lifted, int32_t count, vh_tessellation *out) {
    char *text = NULL;
    size_t size = 0;
    memset(out, 0, sizeof *out);
#ifdef _WIN32
    FILE *messages = fopen("NUL", "w"); /* no stream in memory there: the exit code alone */
#else
    FILE *messages = open_memstream(&text, &size);
#endif
    qhT *qh = calloc(1, sizeof(qhT));
    if (!messages || !qh) {
        if (messages) fclose(messages);
        free(text);
        free(qh);
        out->message = copy_text("could not start Qhull: out of memory");
        return 1;
    }
    int status = tessellate(qh, messages, lifted, count, out);
    int curlong, totlong;
    qh_freeqhull(qh, !qh_ALL);
    qh_memfreeshort(qh, &curlong, &totlong);
    free(qh);
    fclose(messages); /* `text` now holds everything Qhull said */
    if (status > 0) {
        char fallback[64];
        snprintf(fallback, sizeof fallback, "Qhull stopped with exit code %d", status);
        out->message = text && size ? text : copy_text(fallback);
        if (out->message == text) text = NULL;
    }
    free(text);
    return status != 0;
}

void vh_tessellation_free(vh_tessellation *t) {
    free(t->corners);
    free(t->neighbours);
    free(t->message);
    memset(t, 0, sizeof *t);
}
