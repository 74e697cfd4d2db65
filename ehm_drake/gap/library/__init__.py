"""The candidate effects and the linear models the gap diagnosis fits with them."""
