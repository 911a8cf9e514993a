/* The C API's test program (run by tests/capi.rs): opens the .pvs file named on the command
 * line and prints, for each cell, the cell holding its centre, its parent, its visible ids and
 * names, and its is_visible row; each object's source object; then exercises the error values. Exit 1 when the file does not open. */
#include "umbrasweep.h"

#include <stdio.h>
#include <stdlib.h>

int main(int argc, char **argv) {
    char err[256];
    if (argc != 2) {
        fprintf(stderr, "usage: %s FILE.pvs\n", argv[0]);
        return 2;
    }
    UsPvs *pvs = us_pvs_open(argv[1], err, sizeof err);
    if (!pvs) {
        printf("error: %s\n", err);
        return 1;
    }
    uint32_t cells = us_pvs_cell_count(pvs), objects = us_pvs_object_count(pvs);
    printf("cells %u objects %u\n", cells, objects);
    uint32_t *ids = malloc(sizeof(uint32_t) * (objects + 1));
    /* Walk the cells backwards, then forwards: the cursor decodes deltas both ways. */
    for (int pass = 0; pass < 2; pass++) {
        for (uint32_t k = 0; k < cells; k++) {
            uint32_t c = pass == 0 ? cells - 1 - k : k;
            float lo[3], hi[3];
            if (us_pvs_cell_bounds(pvs, c, lo, hi) != 0) return 3;
            int64_t at = us_pvs_cell_at(pvs, 0.5f * (lo[0] + hi[0]), 0.5f * (lo[1] + hi[1]),
                                        0.5f * (lo[2] + hi[2]));
            int64_t n = us_pvs_visible(pvs, c, ids, objects);
            if (n != us_pvs_visible_count(pvs, c)) return 4;
            if (pass == 0) continue;
            printf("cell %u at %lld parent %lld:", c, (long long)at,
                   (long long)us_pvs_cell_parent(pvs, c));
            for (int64_t i = 0; i < n; i++) printf(" %u=%s", ids[i], us_pvs_object_name(pvs, ids[i]));
            printf("\nrow %u: ", c);
            for (uint32_t o = 0; o < objects; o++) printf("%d", us_pvs_is_visible(pvs, c, o));
            printf("\n");
        }
    }
    /* A short buffer still gets the count. */
    if (cells > 0) printf("short %lld\n", (long long)us_pvs_visible(pvs, 0, ids, 1));
    /* Each object's object of the scene file (--split-objects), then the error values. */
    printf("sources");
    for (uint32_t o = 0; o < objects; o++) printf(" %lld", (long long)us_pvs_source_of(pvs, o));
    printf(" %lld %lld\n", (long long)us_pvs_source_of(pvs, objects),
           (long long)us_pvs_cell_parent(pvs, cells));
    printf("errors %lld %lld %d %d %s %lld %u\n", (long long)us_pvs_cell_at(pvs, 1e30f, 0, 0),
           (long long)us_pvs_visible(pvs, cells, ids, objects), us_pvs_is_visible(pvs, cells, 0),
           us_pvs_is_visible(pvs, 0, objects), us_pvs_object_name(pvs, objects) ? "name" : "null",
           (long long)us_pvs_visible_count(NULL, 0), us_pvs_cell_count(NULL));
    free(ids);
    us_pvs_close(pvs);
    us_pvs_close(NULL);
    if (us_pvs_open_bytes((const uint8_t *)"UMBRAPVS", 8, err, sizeof err) != NULL) return 5;
    printf("bytes error: %s\n", err);
    return 0;
}
