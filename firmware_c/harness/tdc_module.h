/*
 * tdc_module.h -- binds the harness and example code to one generated module without knowing its
 * NAME: the build passes -DBIND_NAME=<name> -DBIND_UNAME=<NAME> -DBIND_HEADER="<name>.h" and the
 * code below calls tdc_step(...), tdc_init(...) etc. Nothing here is generated or model-specific.
 */
#ifndef TDC_MODULE_H_INCLUDED
#define TDC_MODULE_H_INCLUDED

#if !defined(BIND_NAME) || !defined(BIND_UNAME) || !defined(BIND_HEADER)
#error "build with -DBIND_NAME=name -DBIND_UNAME=NAME -DBIND_HEADER=\"name.h\" (see firmware_c/Makefile)"
#endif

#include BIND_HEADER

#define TDC_CAT2(a, b) a##b
#define TDC_CAT(a, b) TDC_CAT2(a, b)

#define tdc_state_t TDC_CAT(BIND_NAME, _state_t)
#define tdc_init TDC_CAT(BIND_NAME, _init)
#define tdc_reset TDC_CAT(BIND_NAME, _reset)
#define tdc_step TDC_CAT(BIND_NAME, _step)
#define tdc_run TDC_CAT(BIND_NAME, _run)
#define tdc_model_id TDC_CAT(BIND_NAME, _model_id)
#define TDC_FLAG_TEMP_OUT_OF_RANGE TDC_CAT(BIND_UNAME, _FLAG_TEMP_OUT_OF_RANGE)
#define TDC_FLAG_INPUT_CLAMPED TDC_CAT(BIND_UNAME, _FLAG_INPUT_CLAMPED)
#define TDC_FLAG_SATURATED TDC_CAT(BIND_UNAME, _FLAG_SATURATED)
#define TDC_VALID_TEMP_MIN_MDEGC TDC_CAT(BIND_UNAME, _VALID_TEMP_MIN_MDEGC)
#define TDC_VALID_TEMP_MAX_MDEGC TDC_CAT(BIND_UNAME, _VALID_TEMP_MAX_MDEGC)
#define TDC_SAMPLE_RATE_MILLIHZ TDC_CAT(BIND_UNAME, _SAMPLE_RATE_MILLIHZ)
#define TDC_CHECK_SAMPLE_RATE_MILLIHZ TDC_CAT(BIND_UNAME, _CHECK_SAMPLE_RATE_MILLIHZ)

#endif /* TDC_MODULE_H_INCLUDED */
