/*
 * umbrasweep.h: the C API of the umbrasweep PVS run-time library.
 *
 * Open a binary PVS file (`umbrasweep bake SCENE --cells CELLS.json -o OUT.pvs`, layout in
 * docs/pvs-format.md), find the view cell holding the camera, list or test the objects it
 * may see. Link with -lumbrasweep_capi (cdylib or staticlib from
 * `cargo build -p umbrasweep-capi`; the static library also needs -lpthread -ldl -lm).
 *
 * Every function accepts a NULL handle and out-of-range indices and answers with its error
 * value. The const queries may run on several threads at once; us_pvs_visible moves the
 * handle's cursor, so one thread at a time uses it (open one handle per thread).
 */
#ifndef UMBRASWEEP_H
#define UMBRASWEEP_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* An opened PVS file. */
typedef struct UsPvs UsPvs;

/* Opens and checks a .pvs file (checksum, version, structure). Returns NULL on error and
 * writes a NUL-terminated message (truncated to err_len bytes) to err when it is not NULL. */
UsPvs *us_pvs_open(const char *path, char *err, size_t err_len);

/* As us_pvs_open, from the file's bytes in memory (copied: the buffer may be freed after). */
UsPvs *us_pvs_open_bytes(const uint8_t *data, size_t len, char *err, size_t err_len);

/* Closes a handle; NULL is ignored. */
void us_pvs_close(UsPvs *pvs);

/* Number of cells and of objects (object ids are 0 .. count - 1); 0 for NULL. */
uint32_t us_pvs_cell_count(const UsPvs *pvs);
uint32_t us_pvs_object_count(const UsPvs *pvs);

/* The cell holding the point (boxes are closed; where cells overlap, the lowest index), or
 * -1 when no cell holds it. Uses a uniform grid over the cells. With adaptive subdivision
 * (bake --max-pvs-triangles) it descends to the smallest cell holding the point. */
int64_t us_pvs_cell_at(const UsPvs *pvs, float x, float y, float z);

/* The cell this cell is a half of (adaptive subdivision), or -1 for a cell given to the
 * bake, a bad cell or NULL. */
int64_t us_pvs_cell_parent(const UsPvs *pvs, uint32_t cell);

/* With bake --split-objects: the object of the scene file that object (a cluster) belongs
 * to; without a split, the object itself; -1 for a bad object or NULL. */
int64_t us_pvs_source_of(const UsPvs *pvs, uint32_t object);

/* Writes the cell's box to min[3] and max[3]. 0 on success, -1 for a bad cell. */
int us_pvs_cell_bounds(const UsPvs *pvs, uint32_t cell, float *min, float *max);

/* Number of objects the cell may see, or -1 for a bad cell. */
int64_t us_pvs_visible_count(const UsPvs *pvs, uint32_t cell);

/* Writes the ids of the objects the cell may see, ascending, to out (at most cap of them)
 * and returns how many there are (possibly more than cap), or -1 for a bad cell. Decodes
 * the delta records incrementally from the previous call's cell: walking to a neighbouring
 * cell is cheap. Does not allocate. */
int64_t us_pvs_visible(UsPvs *pvs, uint32_t cell, uint32_t *out, size_t cap);

/* 1 when the cell may see the object, 0 when not (or the object id is out of range), -1 for
 * a bad cell. Does not allocate. */
int us_pvs_is_visible(const UsPvs *pvs, uint32_t cell, uint32_t object);

/* The object's name, NUL-terminated and owned by the handle, or NULL for a bad id. */
const char *us_pvs_object_name(const UsPvs *pvs, uint32_t object);

#ifdef __cplusplus
}
#endif

#endif /* UMBRASWEEP_H */
