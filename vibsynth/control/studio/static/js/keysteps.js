// Keyboard steps of the studio's sliders and XY pad: steps a person can use, whatever the drag
// resolution. A range input's `step` is how finely a drag resolves (0.001 of the intensity); left
// to the browser, an arrow key moves by that step too (7,000 presses across the balance range).
// Here an arrow moves by FINE of the range and Shift+arrow or Page Up/Down by COARSE; Home/End
// keep the browser's (the ends). A moved slider fires `input`, as a drag does, so the panel that
// owns it sends the value exactly as for a drag.

/** One arrow key: this fraction of the range. */
export const FINE = 0.01;
/** Shift+arrow, Page Up, Page Down: this fraction of the range. */
export const COARSE = 0.1;

const DIRECTION = { ArrowRight: 1, ArrowUp: 1, PageUp: 1, ArrowLeft: -1, ArrowDown: -1, PageDown: -1 };

/**
 * The signed fraction of the range a key moves a control by, or null when the key is not a step
 * (Ctrl/Alt/Meta combinations are left to the browser and the system).
 */
export function keyFraction(event) {
  if (event.ctrlKey || event.altKey || event.metaKey) return null;
  const sign = DIRECTION[event.key];
  if (!sign) return null;
  return sign * (event.shiftKey || event.key.startsWith("Page") ? COARSE : FINE);
}

/** `value` moved by `fraction` of [min, max], kept inside it and rounded to `decimals`. */
export function stepValue(value, fraction, min, max, decimals = 3) {
  const moved = Number(value) + fraction * (max - min);
  return Number(Math.max(min, Math.min(max, moved)).toFixed(decimals));
}

function decimalsOf(step) {
  const text = String(step);
  return text.includes(".") ? text.split(".")[1].length : 0;
}

/** Call apply(fraction, event) for each step key pressed on `element` (the key does nothing else). */
export function onStepKeys(element, apply) {
  element.addEventListener("keydown", (event) => {
    const fraction = keyFraction(event);
    if (fraction === null) return;
    event.preventDefault();
    apply(fraction, event);
  });
}

/** Give a range input the keyboard steps; its `step` stays the drag resolution. */
export function keySteps(input) {
  onStepKeys(input, (fraction) => {
    const min = Number(input.min);
    const max = Number(input.max);
    const value = stepValue(input.value, fraction, min, max, Math.max(3, decimalsOf(input.step)));
    if (value === Number(input.value)) return;
    input.value = String(value);
    input.dispatchEvent(new Event("input", { bubbles: true }));
    input.dispatchEvent(new Event("change", { bubbles: true }));
  });
}
