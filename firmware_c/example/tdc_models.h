/*
 * tdc_models.h -- the two compensator modules compiled into the example, under fixed local names.
 *
 * A flight build knows its modules' names (say tdc_x_dlstm and tdc_x_poly3) and calls
 * tdc_x_dlstm_step() directly; this header only exists so that the example builds from any two
 * exports: firmware_c/Makefile passes -DBIND_PRIMARY=<name> -DBIND_PRIMARY_U=<NAME>
 * -DBIND_PRIMARY_HEADER="<name>.h" and the same for BIND_ALT. (So a module must not be named
 * "primary" or "alt", nor upper-case to a BIND_* macro.)
 */
#ifndef TDC_MODELS_H_INCLUDED
#define TDC_MODELS_H_INCLUDED

#if !defined(BIND_PRIMARY) || !defined(BIND_PRIMARY_U) || !defined(BIND_PRIMARY_HEADER) || !defined(BIND_ALT) \
    || !defined(BIND_ALT_U) || !defined(BIND_ALT_HEADER)
#error "build with the BIND_PRIMARY* and BIND_ALT* definitions (see firmware_c/Makefile, target example)"
#endif

#include BIND_PRIMARY_HEADER
#include BIND_ALT_HEADER

#define TDC_CAT2(a, b) a##b
#define TDC_CAT(a, b) TDC_CAT2(a, b)

/* primary model (e.g. the DLSTM) */
#define primary_state_t TDC_CAT(BIND_PRIMARY, _state_t)
#define primary_init TDC_CAT(BIND_PRIMARY, _init)
#define primary_step TDC_CAT(BIND_PRIMARY, _step)
#define primary_model_id TDC_CAT(BIND_PRIMARY, _model_id)
#define PRIMARY_FLAG_TEMP_OUT_OF_RANGE TDC_CAT(BIND_PRIMARY_U, _FLAG_TEMP_OUT_OF_RANGE)
#define PRIMARY_FLAG_INPUT_CLAMPED TDC_CAT(BIND_PRIMARY_U, _FLAG_INPUT_CLAMPED)
#define PRIMARY_FLAG_SATURATED TDC_CAT(BIND_PRIMARY_U, _FLAG_SATURATED)
#define PRIMARY_VALID_TEMP_MIN_MDEGC TDC_CAT(BIND_PRIMARY_U, _VALID_TEMP_MIN_MDEGC)
#define PRIMARY_VALID_TEMP_MAX_MDEGC TDC_CAT(BIND_PRIMARY_U, _VALID_TEMP_MAX_MDEGC)
#define PRIMARY_HOLDS_EDGE_BEYOND_RANGE TDC_CAT(BIND_PRIMARY_U, _HOLDS_EDGE_BEYOND_RANGE)
#define PRIMARY_CHECK_SAMPLE_RATE_MILLIHZ TDC_CAT(BIND_PRIMARY_U, _CHECK_SAMPLE_RATE_MILLIHZ)

/* alternative model (e.g. the cubic: memoryless, cheap, fitted over its own range) */
#define alt_state_t TDC_CAT(BIND_ALT, _state_t)
#define alt_init TDC_CAT(BIND_ALT, _init)
#define alt_step TDC_CAT(BIND_ALT, _step)
#define alt_model_id TDC_CAT(BIND_ALT, _model_id)
#define ALT_FLAG_TEMP_OUT_OF_RANGE TDC_CAT(BIND_ALT_U, _FLAG_TEMP_OUT_OF_RANGE)
#define ALT_FLAG_INPUT_CLAMPED TDC_CAT(BIND_ALT_U, _FLAG_INPUT_CLAMPED)
#define ALT_FLAG_SATURATED TDC_CAT(BIND_ALT_U, _FLAG_SATURATED)
#define ALT_HOLDS_EDGE_BEYOND_RANGE TDC_CAT(BIND_ALT_U, _HOLDS_EDGE_BEYOND_RANGE)
#define ALT_CHECK_SAMPLE_RATE_MILLIHZ TDC_CAT(BIND_ALT_U, _CHECK_SAMPLE_RATE_MILLIHZ)

#endif /* TDC_MODELS_H_INCLUDED */
