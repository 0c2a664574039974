// Sign in, or create an account and sign in with it.
import { post } from '../api.js';
import { h, field, errorBox, showError } from '../dom.js';

const NAME_PATTERN = '[A-Za-z0-9._\\-]{1,64}';

function credentialsForm(idPrefix, submitText, autocomplete) {
  const name = h('input', { id: idPrefix + '-name', name: 'name', required: true, pattern: NAME_PATTERN,
    maxlength: '64', autocomplete: 'username', spellcheck: 'false', autocapitalize: 'off' });
  const password = h('input', { id: idPrefix + '-password', name: 'password', type: 'password',
    required: true, minlength: '8', maxlength: '1024', autocomplete });
  const error = errorBox();
  const button = h('button', { type: 'submit' }, submitText);
  const form = h('form', { class: 'card', novalidate: true },
    field('Name', name, idPrefix === 'new' ? 'Letters, digits, “.”, “_” or “-”; up to 64.' : undefined),
    field('Password', password, idPrefix === 'new' ? 'At least 8 characters.' : undefined),
    error, h('div', { class: 'actions' }, button));
  return { form, name, password, error, button };
}

// Checks the browser can do before asking the server (the server checks again).
function localProblem(f) {
  if (!f.name.validity.valid) return 'Name: 1 to 64 letters, digits, “.”, “_” or “-”.';
  if (!f.password.validity.valid) return 'Password: at least 8 characters.';
  return null;
}

export async function render(main, ctx) {
  const signIn = credentialsForm('signin', 'Sign in', 'current-password');
  const create = credentialsForm('new', 'Create account', 'new-password');

  async function submit(f, makeAccount) {
    showError(f.error, null);
    const problem = localProblem(f);
    if (problem) { showError(f.error, new Error(problem)); return; }
    f.button.disabled = true;
    const body = { name: f.name.value, password: f.password.value };
    try {
      if (makeAccount) await post('/api/v1/accounts', body);
      await post('/api/v1/sessions', body, { quiet401: true });
      await ctx.signedIn();
      if (!ctx.me) throw new Error('Signed in, but the session cookie was not kept: '
        + 'the browser may block cookies for this site.');
      ctx.afterSignIn();
    } catch (e) {
      showError(f.error, e);
      f.button.disabled = false;
    }
  }
  signIn.form.addEventListener('submit', (e) => { e.preventDefault(); submit(signIn, false); });
  create.form.addEventListener('submit', (e) => { e.preventDefault(); submit(create, true); });

  main.append(
    h('h1', {}, 'Sign in'),
    h('p', { class: 'lead' }, 'Collidoscope simulates particles pouring into a vessel and colliding with its walls, and makes a video you can share.'),
    h('ol', { class: 'steps' },
      h('li', {}, h('strong', {}, 'Build a vessel'), ' from shapes, or upload a mesh.'),
      h('li', {}, h('strong', {}, 'Choose the particles'), ' and see what the run will cost before it starts.'),
      h('li', {}, h('strong', {}, 'Watch the video'), ', read the charts, and share a link with your class.')),
    h('div', { class: 'cols' },
      h('section', { 'aria-labelledby': 'signin-h' }, h('h2', { id: 'signin-h' }, 'I have an account'), signIn.form),
      h('section', { 'aria-labelledby': 'new-h' }, h('h2', { id: 'new-h' }, 'Create an account'), create.form)));
}
