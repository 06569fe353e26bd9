#pragma once
// Numpy views of the core's data, as pycolmap gives them: no copy, read-only, kept
// alive by the bound object that owns the data.

#include <pybind11/numpy.h>

#include <utility>
#include <vector>

namespace calibproj::bindings {

// A read-only array over `data`, kept alive by `owner` (the bound object it belongs to).
template <typename T>
pybind11::array ReadOnlyView(const T* data, std::vector<pybind11::ssize_t> shape, const pybind11::handle& owner) {
  pybind11::array view(pybind11::dtype::of<T>(), std::move(shape), {}, data, owner);
  pybind11::detail::array_proxy(view.ptr())->flags &= ~pybind11::detail::npy_api::NPY_ARRAY_WRITEABLE_;
  return view;
}

}  // namespace calibproj::bindings
